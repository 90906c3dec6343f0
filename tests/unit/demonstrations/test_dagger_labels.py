"""DAgger labels (issue 32): the teacher labels, in shadow, the states the student decides on."""

from pathlib import Path

import numpy as np

from pd_core.actions import DEFAULT_ACTIONS
from pd_core.config import DT_S
from pd_core.demonstrations.dagger import label_transitions, student_labels
from pd_core.dqn.config import preset, training_reward
from pd_core.dqn.demo_memory import build_demo_memory
from pd_core.dqn.train import Trainer
from pd_core.dynamics import step
from pd_core.episodes import rollout
from pd_core.runtime.policy_file import load_policy
from pd_core.teachers.zemzev import ZemZevController

POLICY = str(Path(__file__).resolve().parents[3] / "models" / "pd_dqn_best.pt")


def test_labels_are_the_teachers_actions_on_the_states_the_student_flies() -> None:
    d = student_labels(POLICY, "zemzev", 3, 21, dispersions="delay", workers=1)
    flown = rollout(load_policy(POLICY, layer="always"), 3, 21, dispersions="delay")
    assert len(d["labels"]) == len(d["states"]) == len(d["proposed"]) == flown.steps.sum()
    np.testing.assert_array_equal(d["landed"], flown.landed)
    # ZEM/ZEV keeps no memory: its labels are its actions on those states, and the student's
    # own proposals are its network's; the two disagree somewhere (else nothing to learn)
    np.testing.assert_array_equal(d["labels"], ZemZevController().act_batch(d["states"]))
    net = load_policy(POLICY, layer="never").actor
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
    net = load_policy(POLICY, layer="never").actor
    np.testing.assert_array_equal(d["proposed"], net.act_batch(d["states"]))


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
