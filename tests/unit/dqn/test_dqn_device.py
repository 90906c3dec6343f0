"""`pd-train --device`: the device code path (pd_core.dqn.device) flown on the CPU against the
numpy path, its own repeatability and resume, and the paper's update ratio with several envs.

The CUDA graph itself needs a GPU: those tests skip without one (CI has none)."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import torch
from train_configs import small_config

from pd_core.dqn.agent import DQNAgent
from pd_core.dqn.config import TrainConfig, preset
from pd_core.dqn.device import DeviceReplay, DeviceUpdate, resolve_device
from pd_core.dqn.loop import loss_row
from pd_core.dqn.replay import ReplayMemory
from pd_core.dqn.train import Trainer

torch.set_num_threads(1)
needs_cuda = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")


def _small(tmp_path, name: str, base: str = "best", **kw) -> TrainConfig:
    return small_config(tmp_path, name, base, **{"device": "cpu", **kw})


def _weights(tr: Trainer) -> list[torch.Tensor]:
    return [v.detach().cpu().clone() for v in tr.agent.q.state_dict().values()]


def _same(a: Trainer, b: Trainer) -> bool:
    return all(torch.equal(x, y) for x, y in zip(_weights(a), _weights(b), strict=True))


def _transitions(rng: np.random.Generator, n: int) -> tuple[np.ndarray, ...]:
    obs = rng.normal(size=(n, 7)).astype(np.float32)
    return obs, rng.integers(0, 147, n), rng.normal(size=n), obs[::-1].copy(), rng.random(n)


def test_device_replay_holds_what_the_numpy_replay_holds_and_shares_its_checkpoints():
    rng = np.random.default_rng(0)
    host, dev = ReplayMemory(50), DeviceReplay(50)
    for n in (7, 30, 1, 40, 120):  # wraps around, and one batch larger than the capacity
        tr = _transitions(rng, n)
        host.add(*tr)
        dev.add(*tr)
        assert (len(dev), dev.pos) == (len(host), host.pos)
    idx = rng.integers(0, len(host), 64)
    h = host.get(idx)
    for x, y in zip(h[:5], dev.rows(torch.from_numpy(idx)), strict=True):
        assert torch.equal(x, y)
    # one checkpoint format: either memory restores the other
    back, again = ReplayMemory(50), DeviceReplay(50)
    back.load_state_dict(dev.state_dict())
    again.load_state_dict(host.state_dict())
    np.testing.assert_array_equal(back.obs, host.obs)
    assert torch.equal(again.obs, torch.from_numpy(host.obs)) and again.pos == host.pos
    assert float(again.size_t) == 50.0 and int(again.last_t) == 49


def test_device_index_draws_stay_inside_the_filled_rows_and_cover_them():
    cfg = replace(preset("paper-agent2"), hidden=(8,), batch_agent=256)
    agent = DQNAgent(cfg)
    mem = DeviceReplay(1000)
    mem.add(*_transitions(np.random.default_rng(1), 10))
    gen = torch.Generator().manual_seed(0)
    upd = DeviceUpdate(agent, mem, None, generator=gen)
    seen = set()
    for _ in range(5):
        upd()
        ((_, idx, _),) = upd._plans[False].parts
        assert 0 <= int(idx.min()) and int(idx.max()) < 10
        seen |= set(idx.tolist())
    assert seen == set(range(10)) and agent.updates == 5


@pytest.mark.parametrize("base", ["best", "paper-agent1"])
def test_device_code_path_on_cpu_with_the_host_index_draws_reproduces_the_cpu_run_bit_for_bit(
    tmp_path, base
):
    """best: Adam, double DQN, 3-step, Huber, clip, margin loss, pre-training; paper-agent1:
    RMSprop, MSE, 1-step, agent + demonstration rows. Same minibatches -> same weights, bits."""
    host = Trainer(_small(tmp_path, "host", base, seed=4), quiet=True)
    host.run()
    dev = Trainer(_small(tmp_path, "dev", base, seed=4), quiet=True, replay="device-numpy")
    dev.run()
    assert dev.agent.updates == host.agent.updates == 120
    assert _same(host, dev)
    assert (dev.c.episodes, dev.c.env_steps) == (host.c.episodes, host.c.env_steps)
    # the loss parts: tensors read back once on the device path, floats on the numpy one
    np.testing.assert_array_equal(loss_row(dev.last_info), loss_row(host.last_info))
    assert json.loads((tmp_path / "dev" / "config.json").read_text())["run"]["replay"] == (
        "device-numpy"
    )


def test_device_code_path_on_cpu_repeats_for_a_seed_and_resumes_exactly(tmp_path):
    """replay='device': indices from the torch generator (what cuda runs), on the CPU."""
    a = Trainer(_small(tmp_path, "a", seed=2, max_updates=160), quiet=True, replay="device")
    a.run()
    b = Trainer(_small(tmp_path, "b", seed=2, max_updates=160), quiet=True, replay="device")
    b.run()
    assert _same(a, b)
    half = Trainer(_small(tmp_path, "half", seed=2, max_updates=90), quiet=True, replay="device")
    half.run()
    res = Trainer.resume(tmp_path / "half", {"max_updates": 160}, replay="device")
    res.quiet = True
    assert res.agent.updates == 90 and len(res.replay) == len(half.replay)
    res.run()
    assert res.agent.updates == 160 and _same(a, res)
    assert res.c.episodes == a.c.episodes and res.c.env_steps == a.c.env_steps
    # other minibatches than the numpy path's: a different (but as valid) run
    host = Trainer(_small(tmp_path, "host", seed=2, max_updates=160), quiet=True)
    host.run()
    assert not _same(a, host)


def test_a_checkpoint_moves_between_the_paths(tmp_path):
    """A run written on the device path resumes on the numpy path (and so on the CPU of a
    machine without the GPU that wrote it), and the other way round."""
    d = Trainer(_small(tmp_path, "d", seed=3, max_updates=60), quiet=True, replay="device")
    d.run()
    on_host = Trainer.resume(tmp_path / "d", {"max_updates": 100}, replay="host")
    on_host.quiet = True
    assert on_host.run()["updates"] == 100
    back = Trainer.resume(tmp_path / "d", {"max_updates": 140}, replay="device")
    back.quiet = True
    assert back.run()["updates"] == 140


def test_a_capturable_optimiser_state_loads_into_a_cpu_agent():
    """A CUDA-graph run's optimiser state says capturable=True with its step counts on the GPU;
    loaded into a CPU agent it steps there (and a CPU state into a capturable agent too)."""
    cfg = replace(preset("paper-agent2"), hidden=(16,))
    rng = np.random.default_rng(0)
    mem = ReplayMemory(100)
    mem.add(*_transitions(rng, 100))
    torch.manual_seed(0)
    src = DQNAgent(cfg)
    for _ in range(3):
        src.update(mem.sample(32, rng))
    state = src.state_dict()
    for group in state["opt"]["param_groups"]:
        group["capturable"] = True
    dst = DQNAgent(cfg)
    dst.load_state_dict(state)
    assert all(g["capturable"] is False for g in dst.opt.param_groups)
    dst.update(mem.sample(32, rng))
    cap = DQNAgent(cfg, capturable=True)
    cap.load_state_dict(src.state_dict())
    assert all(g["capturable"] is True for g in cap.opt.param_groups)


def test_device_auto_is_the_cpu_without_cuda_and_cuda_is_refused_there(tmp_path, monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert resolve_device("auto") == torch.device("cpu")
    with pytest.raises(ValueError, match="sees no CUDA device"):
        Trainer(_small(tmp_path, "c", device="cuda"), quiet=True)
    assert not (tmp_path / "c").exists()
    tr = Trainer(_small(tmp_path, "auto", device="auto", max_updates=10), quiet=True)
    assert tr.device.type == "cpu" and tr.replay_path == "host" and not tr.cuda_graph
    tr.run()
    run = json.loads((tmp_path / "auto" / "config.json").read_text())["run"]
    assert run["requested"] == "auto" and run["used"] == "cpu" and run["cuda_graph"] is False
    meta = json.loads((tmp_path / "auto" / "final.json").read_text())
    assert "cpu" in json.dumps(meta)


def test_one_update_per_env_transition_with_several_envs(tmp_path):
    """The paper's ratio with 4 envs: updates_per_step = num_envs; max_updates is exact even
    when it falls inside a step's burst of updates."""
    cfg = _small(
        tmp_path, "r", num_envs=4, updates_per_step=4.0, n_step=1, pretrain_updates=0,
        max_updates=50, learning_starts=200,
    )  # fmt: skip
    tr = Trainer(cfg, quiet=True)
    out = tr.run()
    assert out["updates"] == 50
    # 4 updates after each step of the 4 envs from the one that stores the 200th transition:
    # 13 steps, the last one cut to 2 updates by max_updates
    assert tr.c.env_steps == 200 + 4 * 12 and tr.c.update_credit == 2.0


@needs_cuda
def test_cuda_graph_step_agrees_with_the_eager_step_on_the_same_minibatches():
    cfg = replace(preset("paper-agent1"), hidden=(300, 200, 300), double_dqn=True, loss="huber")
    agents, updates = [], []
    for graph in (False, True):
        torch.manual_seed(0)
        agent = DQNAgent(cfg, device="cuda", capturable=graph)
        mem, demo = DeviceReplay(5000, device="cuda"), DeviceReplay(1000, device="cuda")
        tr = _transitions(np.random.default_rng(1), 5000)
        mem.add(*tr)
        demo.add(*(x[:1000] for x in tr))
        upd = DeviceUpdate(agent, mem, demo, graph=graph, index_rng=np.random.default_rng(2))
        agents.append(agent)
        updates.append(upd)
    for _ in range(20):  # 3 warm-up steps, the capture, 16 replays
        for upd in updates:
            upd()
    assert updates[1]._plans[False].graph is not None
    for x, y in zip(agents[0].q.parameters(), agents[1].q.parameters(), strict=True):
        torch.testing.assert_close(x, y, rtol=1e-4, atol=1e-6)


@needs_cuda
def test_a_cuda_run_trains_in_a_graph_and_resumes_on_the_cpu(tmp_path):
    tr = Trainer(_small(tmp_path, "g", seed=1, device="cuda", max_updates=60), quiet=True)
    assert tr.cuda_graph and tr.replay_path == "device"
    tr.run()
    run = json.loads((tmp_path / "g" / "config.json").read_text())["run"]
    assert run["used"].startswith("cuda") and run["cuda_graph"] is True
    res = Trainer.resume(tmp_path / "g", {"max_updates": 90, "device": "cpu"})
    res.quiet = True
    assert res.run()["updates"] == 90
