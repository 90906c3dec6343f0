"""DAgger labels (issue 32): the teacher labels, in shadow, the states the student decides on."""

from pathlib import Path

import numpy as np

from pd_core.actions import DEFAULT_ACTIONS
from pd_core.config import DT_S
from pd_core.demonstrations.dagger import label_transitions, student_labels
from pd_core.dispersions import failure_weights
from pd_core.dqn.config import preset
from pd_core.dqn.demo_memory import build_demo_memory, label_scenario_probs
from pd_core.dqn.train import Trainer, training_reward
from pd_core.dynamics import step
from pd_core.experiments.evaluate import rollout
from pd_core.runtime.policy_file import load_policy
from pd_core.teachers.zemzev import ZemZevController

POLICY = str(Path(__file__).resolve().parents[2] / "models" / "pd_dqn_best.pt")


def test_labels_are_the_teachers_actions_on_the_states_the_student_flies() -> None:
    d = student_labels(POLICY, "zemzev", 3, 21, dispersions="delay", workers=1)
    flown = rollout(load_policy(POLICY, shield="always"), 3, 21, dispersions="delay")
    assert len(d["labels"]) == len(d["states"]) == len(d["proposed"]) == flown.steps.sum()
    np.testing.assert_array_equal(d["landed"], flown.landed)
    # ZEM/ZEV keeps no memory: its labels are its actions on those states, and the student's
    # own proposals are its network's; the two disagree somewhere (else nothing to learn)
    np.testing.assert_array_equal(d["labels"], ZemZevController().act_batch(d["states"]))
    net = load_policy(POLICY, shield="never").actor
    np.testing.assert_array_equal(d["proposed"], net.act_batch(d["states"]))
    assert 0.0 < np.mean(d["labels"] != d["proposed"]) < 1.0


def test_label_noise_flies_random_actions_on_that_share_of_steps_and_labels_them_all() -> None:
    clean = student_labels(POLICY, "zemzev", 3, 21, dispersions="delay", workers=1)
    np.testing.assert_array_equal(clean["flown"], clean["proposed"])
    d = student_labels(POLICY, "zemzev", 3, 21, dispersions="delay", workers=1, noise=0.3)
    again = student_labels(POLICY, "zemzev", 3, 21, dispersions="delay", workers=1, noise=0.3)
    np.testing.assert_array_equal(d["states"], again["states"])  # seeded by the episodes
    # 0.3 of the steps fly one of the 147 actions drawn uniformly (1 in 147 is its own);
    # ~700 steps: the share's sd is ~0.017
    assert abs(np.mean(d["flown"] != d["proposed"]) - 0.3 * 146 / 147) < 0.07
    assert len(d["states"]) != len(clean["states"])  # the flights differ
    # every state is still labelled by the teacher, and proposed is still the network's own
    np.testing.assert_array_equal(d["labels"], ZemZevController().act_batch(d["states"]))
    net = load_policy(POLICY, shield="never").actor
    np.testing.assert_array_equal(d["proposed"], net.act_batch(d["states"]))


def test_label_episodes_draw_their_scenarios_with_the_given_probabilities() -> None:
    uniform = student_labels(POLICY, "zemzev", 6, 21, dispersions="delay,gusts", workers=1)
    flown = rollout(load_policy(POLICY, shield="always"), 6, 21, dispersions="delay,gusts")
    np.testing.assert_array_equal(uniform["scenarios"], flown.scenarios)  # default unchanged
    assert set(uniform["scenarios"]) == {0, 1}  # seeds 21-26 draw both
    gusts = student_labels(
        POLICY, "zemzev", 6, 21, dispersions="delay,gusts", workers=1, scenario_probs=[0.0, 1.0]
    )
    assert gusts["scenarios"].tolist() == [1] * 6


def test_failure_sampling_draws_the_next_round_where_the_student_failed_in_the_last() -> None:
    last = {"scenario_episodes": [10, 10, 10], "scenario_failures": [0, 5, 10]}
    cfg = preset("ocp-dagger", scenario_sampling="failures", scenario_uniform_share=0.5)
    probs = label_scenario_probs(cfg, last)
    # Laplace-smoothed rates 1/12, 6/12, 11/12: half uniform, half in their proportion
    np.testing.assert_allclose(probs, [1 / 6 + 0.5 / 18, 1 / 6 + 3 / 18, 1 / 6 + 5.5 / 18])
    assert label_scenario_probs(preset("ocp-dagger"), last) is None  # uniform sampling
    assert label_scenario_probs(cfg, None) is None  # no round before (no init policy)
    one = {"scenario_episodes": [10], "scenario_failures": [4]}
    assert label_scenario_probs(cfg, one) is None  # one scenario: nothing to weigh


def test_failure_sampled_dagger_rounds_record_their_draw_and_counts(tmp_path: Path) -> None:
    cfg = preset(
        "best", controller="zemzev", controller_demo_episodes=2, label_episodes=4,
        dagger_rounds=2, pretrain_updates=10, num_envs=2, eval_episodes=2, eval_every_s=0.0,
        progress=False, torch_threads=1, max_minutes=10.0, dispersions="delay,gusts",
        scenario_sampling="failures",
    )  # fmt: skip
    trainer = Trainer(cfg, run_dir=tmp_path, quiet=True)
    trainer.run()
    first, second = trainer.demo_info["dagger_rounds"]
    assert first["scenario_probs"] is None  # no labelled round before it (no init policy)
    assert sum(first["scenario_episodes"]) == 4 and len(first["scenario_episodes"]) == 2
    want = failure_weights(
        np.array(first["scenario_failures"]), np.array(first["scenario_episodes"]), 0.5
    )
    np.testing.assert_allclose(second["scenario_probs"], want)


def test_label_transitions_step_the_nominal_dynamics() -> None:
    s = np.array([[10.0, -5.0, 300.0, 1.0, 0.5, -20.0, 1900.0], [0.1, 0.0, 0.05, 0, 0, -1.0, 1700]])
    t = label_transitions(s, np.array([100, 3]))
    want = step(s, DEFAULT_ACTIONS.thrust(np.array([100, 3])), np.zeros((2, 3)), DT_S)
    np.testing.assert_allclose(t["next_states"], want)
    assert t["dones"].tolist() == [False, True]  # the second one touches down
    assert t["episode"].tolist() == [0, 1]  # each label stands alone


def test_demo_memory_takes_the_labels_of_the_init_policy() -> None:
    cfg = preset(
        "best", controller="zemzev", controller_demo_episodes=0, label_episodes=2,
        init_policy=POLICY, dispersions="gusts", n_step=3,
    )  # fmt: skip
    memory, info = build_demo_memory(cfg, training_reward(cfg))
    assert info["labels"]["episodes"] == 2 and info["labels"]["teacher"] == "zemzev"
    assert len(memory) == info["labels"]["labels"] > 100
    assert 0.0 < info["labels"]["agreement"] <= 1.0


def test_dagger_rounds_add_labels_of_the_current_network_and_end_the_run(tmp_path: Path) -> None:
    cfg = preset(
        "best", controller="zemzev", controller_demo_episodes=2, label_episodes=2,
        dagger_rounds=2, pretrain_updates=30, num_envs=2, eval_episodes=2, eval_every_s=0.0,
        progress=False, torch_threads=1, max_minutes=10.0,
    )  # fmt: skip
    trainer = Trainer(cfg, run_dir=tmp_path, quiet=True)
    demos = len(trainer.demo)
    out = trainer.run()
    rounds = trainer.demo_info["dagger_rounds"]
    assert out["stop_reason"] == "dagger_rounds" and out["episodes"] == 0  # no interaction
    assert out["updates"] == 3 * 30  # pre-training before, between and after the rounds
    assert [r["round"] for r in rounds] == [1, 2] and all(r["episodes"] == 2 for r in rounds)
    # aggregated: every earlier demonstration stays, each round's labels join them
    assert len(trainer.demo) == demos + sum(r["labels"] for r in rounds) > demos + 200
    assert (tmp_path / "dagger_student.pt").is_file()
    resumed = Trainer.resume(tmp_path)
    assert resumed.dagger_round == 2 and len(resumed.demo) == len(trainer.demo)
