"""Training runs: repeatable for a seed, resumable, and better than a random policy."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
import torch
from train_configs import small_config

from pd_core.dqn.actor import TorchGreedy
from pd_core.dqn.config import TrainConfig, preset
from pd_core.dqn.train import Trainer, train
from pd_core.episodes import rollout, summarise
from pd_core.runtime.config import RuntimeConfig
from pd_core.runtime.layer import Runtime
from pd_core.runtime.policy_file import load_policy, read_policy

torch.set_num_threads(1)
NOMINAL_POLICY = str(Path(__file__).resolve().parents[3] / "models" / "pd_dqn_best.pt")


def _small(tmp_path, name: str, **kw) -> TrainConfig:
    return small_config(tmp_path, name, **kw)


def _weights(tr: Trainer) -> list[torch.Tensor]:
    return [v.clone() for v in tr.agent.q.state_dict().values()]


def test_same_seed_same_weights_after_n_updates(tmp_path):
    a = Trainer(_small(tmp_path, "a", seed=5), quiet=True)
    a.run()
    b = Trainer(_small(tmp_path, "b", seed=5), quiet=True)
    b.run()
    assert a.agent.updates == b.agent.updates == 120
    for x, y in zip(_weights(a), _weights(b), strict=True):
        assert torch.equal(x, y)
    c = Trainer(_small(tmp_path, "c", seed=6), quiet=True)
    c.run()
    assert not all(torch.equal(x, y) for x, y in zip(_weights(a), _weights(c), strict=True))


def test_resume_continues_exactly(tmp_path):
    full = Trainer(_small(tmp_path, "full", seed=2, max_updates=160), quiet=True)
    full.run()
    half = Trainer(_small(tmp_path, "half", seed=2, max_updates=90), quiet=True)
    half.run()
    res = Trainer.resume(tmp_path / "half", {"max_updates": 160})
    res.quiet = True
    # restored: networks, optimiser, memories and schedules
    assert res.agent.updates == 90 and len(res.replay) == len(half.replay)
    assert res.c.episodes == half.c.episodes and res.pretrained == half.pretrained
    np.testing.assert_array_equal(res.demo.obs, half.demo.obs)
    res.run()
    assert res.agent.updates == 160
    for x, y in zip(_weights(full), _weights(res), strict=True):
        assert torch.equal(x, y)
    assert res.c.episodes == full.c.episodes and res.c.env_steps == full.c.env_steps


def test_weight_average_is_what_flies_and_resumes_exactly(tmp_path):
    full = Trainer(
        _small(tmp_path, "full", seed=2, max_updates=160, weight_average=0.99), quiet=True
    )
    full.run()
    half = Trainer(
        _small(tmp_path, "half", seed=2, max_updates=90, weight_average=0.99), quiet=True
    )
    half.run()
    res = Trainer.resume(tmp_path / "half", {"max_updates": 160})
    res.quiet = True
    res.run()
    avg = [v.clone() for v in full.agent.q_avg.state_dict().values()]
    for x, y in zip(avg, res.agent.q_avg.state_dict().values(), strict=True):
        assert torch.equal(x, y)
    # the saved policy holds the average, not the online weights
    _, tensors = read_policy(full.run_dir / "final.pt")
    for name, x in full.agent.q_avg.state_dict().items():
        assert torch.equal(x, torch.as_tensor(tensors[name]))
    assert not all(torch.equal(x, y) for x, y in zip(avg, _weights(full), strict=True))


def test_demo_memory_untouched_by_training(tmp_path):
    tr = Trainer(_small(tmp_path, "d", seed=1), quiet=True)
    before = (tr.demo.obs.copy(), tr.demo.actions.copy(), tr.demo.rewards.copy())
    tr.run()
    for x, y in zip(before, (tr.demo.obs, tr.demo.actions, tr.demo.rewards), strict=True):
        np.testing.assert_array_equal(x, y)


class _Random:
    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)

    def act_batch(self, states: np.ndarray) -> np.ndarray:
        return self.rng.integers(0, 147, size=len(states))


@pytest.mark.slow
def test_short_training_beats_random_policy(tmp_path):
    cfg = _small(
        tmp_path,
        "short",
        seed=3,
        hidden=(64, 64),
        controller_demo_episodes=20,
        pretrain_updates=600,
        max_updates=700,
        batch_agent=32,
        batch_demo=32,
        lr=1e-3,
        input_norm_init=True,
    )
    out = train(cfg, quiet=True)
    assert out["updates"] == 700
    tr = Trainer.resume(tmp_path / "short")
    trained = summarise(rollout(TorchGreedy(tr.agent.q), 50, seed=123))
    rand = summarise(rollout(_Random(0), 50, seed=123))
    # a random policy spends its time far off the target velocity: much lower return
    # a random policy hits the ground at ~ -86 m/s (median, 50 episodes); the seeded short run
    # (700 updates, mostly imitation of the reference controller) brakes to about -35 m/s.
    kv = trained["table7"]["k_velocity_mps"]["median"]
    kv_rand = rand["table7"]["k_velocity_mps"]["median"]
    assert kv > kv_rand + 25.0, (kv, kv_rand)
    assert (
        trained["table7"]["norm_ij_position_m"]["median"]
        < 0.9 * (rand["table7"]["norm_ij_position_m"]["median"])
    )


def test_init_policy_starts_from_the_shipped_weights_and_refuses_another_shape(tmp_path):
    src = Trainer(_small(tmp_path, "src", seed=3), quiet=True)
    src.run()
    shipped = str(tmp_path / "src" / "final.pt")
    tuned = Trainer(_small(tmp_path, "tuned", seed=4, init_policy=shipped), quiet=True)
    for x, y in zip(_weights(src), _weights(tuned), strict=True):
        assert torch.equal(x, y)
    target = [v.clone() for v in tuned.agent.q_target.state_dict().values()]
    for x, y in zip(_weights(src), target, strict=True):
        assert torch.equal(x, y)
    with pytest.raises(ValueError, match="differs from the config"):
        Trainer(_small(tmp_path, "bad", init_policy=shipped, hidden=(16, 16)), quiet=True)


def test_a_paper_network_is_widened_for_near_pad_inputs_without_changing_a_value(tmp_path):
    src = Trainer(_small(tmp_path, "src", seed=3), quiet=True)
    src.run()
    tuned = Trainer(
        _small(
            tmp_path, "wide", seed=4, init_policy=str(tmp_path / "src" / "final.pt"), near_pad=True
        ),
        quiet=True,
    )
    assert tuned.agent.q.net[0].weight.shape == (32, 13)
    obs = torch.from_numpy(tuned.demo.obs[:500])  # demonstration states, down to the pad
    with torch.no_grad():
        want = src.agent.q(obs)
        torch.testing.assert_close(tuned.agent.q(obs), want, atol=1e-5, rtol=0)
        torch.testing.assert_close(tuned.agent.q_target(obs), want, atol=1e-5, rtol=0)


def test_max_minutes_counts_the_demonstrations_built_at_start(tmp_path):
    # a budget far shorter than building 32 teacher episodes: the run stops before any update,
    # and its wall time includes the building (a clock restarted by `run` would read ~0 here)
    t0 = time.perf_counter()
    tr = Trainer(
        _small(tmp_path, "clock", controller_demo_episodes=32, max_minutes=1e-5), quiet=True
    )
    built = time.perf_counter() - t0
    out = tr.run()
    assert built > 0.02
    assert out["stop_reason"] == "max_minutes"
    assert tr.pretrained == 0 and out["episodes"] == 0 and out["updates"] == 0
    assert out["wall_s"] >= 0.8 * built


def test_failure_weighted_scenarios_follow_training_failures_and_resume(tmp_path):
    # from pd_dqn_best (the nominal-problem policy), barely changed (lr 1e-7): it lands
    # `nominal` and fails `all` about half the time
    cfg = _small(
        tmp_path, "sf", seed=3, dispersions="nominal,all", scenario_sampling="failures",
        scenario_uniform_share=0.2, max_updates=1500, num_envs=32, pretrain_updates=0,
        init_policy=NOMINAL_POLICY, hidden=preset("best").hidden, epsilon0=0.0,
        lr=1e-7, lr_finetune=1e-7,
    )  # fmt: skip
    tr = Trainer(cfg, quiet=True)
    tr.run()
    fails = tr.outcomes.failure_rates()
    p = tr.env.scenario_probs
    flown = [len(r) for r in tr.outcomes.recent]
    assert fails[0] < 0.05 and fails[1] > 0.2, fails
    assert flown[1] > 2 * flown[0], flown  # the draws went where it fails
    np.testing.assert_allclose(p, tr.outcomes.probs())
    assert p[1] > 0.6 and p[0] >= 0.1  # most draws go where it fails; the floor stays
    res = Trainer.resume(tmp_path / "sf", {"max_updates": 1500})
    assert [list(r) for r in res.outcomes.recent] == [list(r) for r in tr.outcomes.recent]
    np.testing.assert_allclose(res.env.scenario_probs, p)
    rows = (tmp_path / "sf" / "scenarios.csv").read_text().splitlines()
    assert rows[0].startswith("wall_s,episodes,p_nominal,p_all,fail_nominal,fail_all")


def test_a_run_with_the_layer_evaluates_behind_it_and_files_ask_for_it(tmp_path):
    tr = Trainer(_small(tmp_path, "sh", seed=5, layer=True), quiet=True)
    tr.run()
    assert load_policy(tmp_path / "sh" / "final.pt").config == RuntimeConfig()
    # an untrained network crashes; behind the layer it touches down far slower, and the
    # periodic evaluation (which picks best.pt) is the flight behind the layer
    behind = rollout(Runtime(TorchGreedy(tr.agent.q), RuntimeConfig()), 20, 0)
    bare = rollout(TorchGreedy(tr.agent.q), 20, 0)
    assert behind.final_states[:, 5].min() > bare.final_states[:, 5].min() + 5.0
    vk = summarise(behind)["table7"]["k_velocity_mps"]["min"]
    assert tr.evaluate(episodes=20, seed=0)["kvel_min"] == pytest.approx(vk, abs=1e-9)


def test_evaluations_by_updates_fall_on_fixed_update_counts_once_each(tmp_path):
    # every 40 gradient updates (20 of pre-training, then interaction), whatever the clock;
    # the run's last network (120 updates) is evaluated once, not again at the end
    tr = Trainer(_small(tmp_path, "eu", eval_every_updates=40, eval_episodes=2), quiet=True)
    tr.run()
    rows = (tmp_path / "eu" / "evals.csv").read_text().splitlines()[1:]
    assert [int(r.split(",")[1]) for r in rows] == [40, 80, 120]
    assert tr.c.last_eval_updates == 120
