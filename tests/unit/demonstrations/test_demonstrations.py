"""Controller demonstrations for the DQfD memory: flown under the training dispersions, split
between teachers, filtered to the episodes that landed, and started where the student goes."""

from pathlib import Path

import numpy as np
import pytest

from pd_core.demonstrations.teacher_flown import controller_demonstrations
from pd_core.dqn import demo_memory
from pd_core.dqn.config import preset, training_reward
from pd_core.dqn.demo_memory import (
    build_demo_memory,
    controller_steps,
    recovery_starts,
    recovery_steps,
)
from pd_core.episodes import rollout
from pd_core.runtime.config import RuntimeConfig
from pd_core.runtime.layer import Runtime
from pd_core.runtime.policy_file import load_policy
from pd_core.teachers.zemzev import ZemZevController


def test_controller_demonstrations_fly_the_dispersed_masses() -> None:
    d = controller_demonstrations("zemzev", 12, 5, dispersions="mass", workers=1)
    first = np.flatnonzero(np.r_[True, d["episode"][1:] != d["episode"][:-1]])
    m0 = d["states"][first, 6]
    assert len(m0) == 12
    assert np.all((m0 >= 1800.0) & (m0 <= 2200.0))
    assert np.ptp(m0) > 100.0  # Table 3 alone would give 2000 kg every time
    assert d["landed"].shape == (12,)
    assert float(d["success_rate"]) == d["landed"].mean()


def test_demonstrations_behind_the_layer_hold_the_actions_it_flies() -> None:
    # two steps of delay: the layer decides on the predicted state, so the flown actions differ
    bare = controller_demonstrations("zemzev", 6, 3, dispersions="delay-2", workers=1)
    layer = controller_demonstrations(
        "zemzev", 6, 3, dispersions="delay-2", workers=1, behind_layer=True
    )
    flown = rollout(
        Runtime(ZemZevController(), RuntimeConfig()), 6, 3, dispersions="delay-2",
        keep_trajectories=6,
    )  # fmt: skip
    np.testing.assert_array_equal(layer["actions"], np.concatenate(flown.actions))
    np.testing.assert_array_equal(layer["landed"], flown.landed)
    n = min(len(bare["actions"]), len(layer["actions"]))
    assert (bare["actions"][:n] != layer["actions"][:n]).mean() > 0.05


def test_landed_only_keeps_exactly_the_landed_episodes() -> None:
    every, rate = controller_steps("zemzev", 24, 7, "all")
    kept, rate_kept = controller_steps("zemzev", 24, 7, "all", landed_only=True)
    assert rate == rate_kept < 1.0  # the `all` scenario makes ZEM/ZEV fail some episodes
    landed = controller_demonstrations("zemzev", 24, 7, dispersions="all", workers=1)["landed"]
    assert set(np.unique(kept.episode)) == set(np.flatnonzero(landed))
    mask = landed[every.episode]
    np.testing.assert_array_equal(kept.actions, every.actions[mask])
    np.testing.assert_array_equal(kept.states, every.states[mask])


def test_demo_memory_splits_episodes_between_teachers() -> None:
    cfg = preset(
        "best", controller="zemzev, zemzev", controller_demo_episodes=5, dispersions="gusts"
    )
    memory, info = build_demo_memory(cfg, training_reward(cfg))
    assert [c["episodes"] for c in info["controller"]] == [3, 2]
    assert all(c["dispersions"] == "gusts" for c in info["controller"])
    assert len(memory) == sum(c["transitions"] for c in info["controller"])


POLICY = str(Path(__file__).resolve().parents[3] / "models" / "pd_dqn_best.pt")


def test_recovery_demonstrations_start_on_the_students_own_paths() -> None:
    starts, seeds, student = recovery_starts(POLICY, 8, 11, "delay")
    np.testing.assert_array_equal(seeds, np.arange(11, 19))
    ro = rollout(load_policy(POLICY), 8, 11, keep_trajectories=8, dispersions="delay")
    assert student == ro.landed.mean()
    for s, path in zip(starts, ro.trajectories, strict=True):
        # a state of the path before touchdown (the last state is the terminal one)
        assert np.min(np.abs(path[:-1] - s).max(axis=1)) == 0.0
    assert np.ptp(starts[:, 2]) > 100.0  # drawn along the descent, not always the first state
    steps, teacher, again = recovery_steps(POLICY, "zemzev", 8, 11, "delay")
    assert again == student and 0.0 <= teacher <= 1.0
    first = np.flatnonzero(np.r_[True, steps.episode[1:] != steps.episode[:-1]])
    np.testing.assert_array_equal(steps.states[first], starts)  # the teacher flies on from there
    np.testing.assert_array_equal(steps.actions, ZemZevController().act_batch(steps.states))


def test_recovery_starts_from_the_students_failures(monkeypatch) -> None:
    monkeypatch.setattr(demo_memory, "FAILURE_SEARCH_CHUNK", 40)
    # pd_dqn_best lands about half of `all`: 3 starts from any episode, 5 from failed ones
    starts, seeds, student = recovery_starts(POLICY, 8, 11, "all", failed_share=0.6)
    np.testing.assert_array_equal(seeds[:3], [11, 12, 13])
    assert len(set(seeds[3:])) == 5 and min(seeds[3:]) >= 14 and 0.2 < student < 0.8
    again = rollout(
        load_policy(POLICY), 5, 0, keep_trajectories=5, dispersions="all", episode_seeds=seeds[3:]
    )
    assert not again.landed.any()  # each comes from an episode the student crashed
    for s, path in zip(starts[3:], again.trajectories, strict=True):
        assert np.min(np.abs(path[:-1] - s).max(axis=1)) == 0.0
    steps, _, _ = recovery_steps(POLICY, "zemzev", 8, 11, "all", failed_share=0.6)
    first = np.flatnonzero(np.r_[True, steps.episode[1:] != steps.episode[:-1]])
    np.testing.assert_array_equal(steps.states[first], starts)


def test_rollout_episode_seeds_fly_those_episodes() -> None:
    ctl = ZemZevController()
    picked = rollout(ctl, 3, 0, dispersions="all", episode_seeds=[7, 3, 20], chunk=2)
    for k, s in enumerate((7, 3, 20)):
        one = rollout(ctl, 1, s, dispersions="all")
        np.testing.assert_array_equal(picked.final_states[k], one.final_states[0])


def test_recovery_demonstrations_need_a_student() -> None:
    cfg = preset("best", recovery_demo_episodes=4, controller_demo_episodes=0)
    with pytest.raises(ValueError, match="init_policy"):
        build_demo_memory(cfg, training_reward(cfg))
    cfg = preset("robust", init_policy=POLICY, recovery_demo_episodes=4, controller_demo_episodes=0)
    memory, info = build_demo_memory(cfg, training_reward(cfg))
    assert info["recovery"]["student"] == POLICY and info["recovery"]["episodes"] == 4
    assert len(memory) == info["recovery"]["transitions"] > 0
