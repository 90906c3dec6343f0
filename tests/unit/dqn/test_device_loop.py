"""`pd-train --loop device` (pd_core.dqn.device_loop, pd_core.dqn.stacked) against the reference
loop (pd_core.dqn.train) on the CPU: the same update, the same counts, the same Q-values where it
draws the reference's minibatches, several agents at once as each alone, and Table 2 only.

The CUDA graph of a block needs a GPU: those tests skip without one (CI has none)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from pd_core.cli import train as pd_train
from pd_core.dqn.agent import DQNAgent
from pd_core.dqn.config import TrainConfig, preset
from pd_core.dqn.device_loop import DeviceLoop, device_loop_unsupported, uses_device_loop
from pd_core.dqn.network import QNetwork
from pd_core.dqn.replay import ReplaySample
from pd_core.dqn.stacked import StackedQ, td_output_grad
from pd_core.dqn.train import Trainer

torch.set_num_threads(1)
needs_cuda = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
PROBE = torch.randn(500, 7, generator=torch.Generator().manual_seed(7))
TOLERANCE = 1e-5
"""|Q| difference allowed between the two loops on the probe states after a short run: float32
rounding of the same arithmetic in another order (bias inside the matrix product)"""


def _cfg(tmp_path: Path, name: str, base: str = "paper-agent1", **kw) -> TrainConfig:
    """Table 2 at the paper's ratio (16 envs, 16 updates a step), short: 640 updates."""
    fields = dict(
        seed=3, num_envs=16, updates_per_step=16.0, learning_starts=208, max_updates=640,
        buffer_size=4000, eval_every_s=0.0, checkpoint_every_s=1e9, progress=False,
        device="cpu", run_dir=str(tmp_path / name),
    )  # fmt: skip
    return replace(preset(base), **{**fields, **kw})


def _q(net: QNetwork) -> torch.Tensor:
    with torch.no_grad():
        return net(PROBE)


def _initial_q(seed: int) -> torch.Tensor:
    torch.manual_seed(seed)
    return _q(QNetwork())


def test_stacked_update_is_the_reference_update_rmsprop_and_target_copy_included():
    cfg = preset("paper-agent1")
    torch.manual_seed(1)
    agent = DQNAgent(cfg)
    q = StackedQ.from_networks([agent.q], cfg.lr)
    b, gen = 200, torch.Generator().manual_seed(0)
    x, buf, dq = q.inputs(2, b), q.buffers(2, b), torch.zeros(1, b, 147)
    for i in range(1, 131):  # two target copies (n_T = 65)
        obs, nobs = torch.randn(b, 7, generator=gen), torch.randn(b, 7, generator=gen)
        a = torch.randint(0, 147, (b,), generator=gen)
        r, d = torch.randn(b, generator=gen), torch.full((b,), cfg.gamma)
        agent.update(ReplaySample(obs, a, r, nobs, d, torch.zeros(b, dtype=torch.bool)))
        x[0, :, :7], x[1, :, :7] = obs, nobs
        out = q.forward(x, buf)
        td_output_grad(out, a[None], r[None], d[None], torch.full((1, 1), 2.0 / b), dq)
        q.backward(x, buf, dq)
        q.rmsprop_step()
        q.copy_target_where(torch.tensor(i % cfg.target_period == 0))
    moved = (_q(agent.q) - _initial_q(1)).abs().max()
    assert moved > 0.05  # 5000 x the tolerance
    assert (_q(q.network(0)) - _q(agent.q)).abs().max() < TOLERANCE
    assert (_q(q.network(0, target=True)) - _q(agent.q_target)).abs().max() < TOLERANCE


@pytest.mark.parametrize("base", ["paper-agent1", "paper-agent2"])
def test_with_the_reference_draws_the_device_loop_is_the_reference_loop(tmp_path, base):
    ref = Trainer(_cfg(tmp_path, "ref", base), quiet=True)
    s_ref = ref.run()
    loop = DeviceLoop([_cfg(tmp_path, "dev", base)], host_indices=True, quiet=True)
    [s_dev] = loop.run()
    for k in ("env_steps", "updates", "episodes", "successes"):
        assert s_dev[k] == s_ref[k], k
    assert s_dev["updates"] == 640
    assert (_q(ref.agent.q) - _initial_q(3)).abs().max() > 0.1
    assert (_q(loop.q.network(0)) - _q(ref.agent.q)).abs().max() < TOLERANCE
    assert Path(s_dev["final_policy"]).exists()
    assert (tmp_path / "dev" / "episodes.csv").exists()


def test_device_draws_and_overlap_count_exactly_as_the_reference(tmp_path):
    ref = Trainer(_cfg(tmp_path, "ref"), quiet=True).run()
    loop = DeviceLoop([_cfg(tmp_path, "dev")], overlap=True, quiet=True)
    [dev] = loop.run()
    assert (dev["env_steps"], dev["updates"]) == (ref["env_steps"], ref["updates"])
    q = _q(loop.q.network(0))
    assert torch.isfinite(q).all() and (q - _initial_q(3)).abs().max() > 0.1


def test_agents_together_learn_as_each_alone_and_stop_at_their_own_count(tmp_path):
    one = _cfg(tmp_path, "a1", max_updates=320)
    two = _cfg(tmp_path, "a2", "paper-agent2", seed=5, max_updates=640)
    together = DeviceLoop([one, two], host_indices=True, quiet=True)
    s = together.run()
    assert [x["updates"] for x in s] == [320, 640]
    for i, cfg in enumerate((one, two)):
        alone = DeviceLoop([replace(cfg, run_dir=f"{cfg.run_dir}_alone")], host_indices=True)
        [s_alone] = alone.run()
        assert s[i]["env_steps"] == s_alone["env_steps"]
        diff = _q(together.q.network(i)) - _q(alone.q.network(0))
        assert diff.abs().max() < TOLERANCE


def test_a_resumed_loop_continues_bit_for_bit(tmp_path):
    whole = DeviceLoop([_cfg(tmp_path, "whole")])
    [s_whole] = whole.run()
    half = DeviceLoop([_cfg(tmp_path, "half", max_updates=320)])
    half.run()
    assert (tmp_path / "half" / "checkpoint.pt").exists()
    again = DeviceLoop.resume(tmp_path / "half", {"max_updates": 640})
    [s_again] = again.run()
    for k in ("env_steps", "updates", "episodes"):
        assert s_again[k] == s_whole[k], k
    assert torch.equal(_q(again.q.network(0)), _q(whole.q.network(0)))
    rows = [
        len((tmp_path / n / "episodes.csv").read_text().splitlines()) for n in ("whole", "half")
    ]
    assert rows[0] == rows[1]


def test_pd_train_resumes_a_device_loop_run(tmp_path, capsys):
    argv = ["--preset", "paper-agent2", "--loop", "device", "--num-envs", "16"]
    argv += ["--updates-per-step", "16", "--learning-starts", "208", "--eval-every-s", "0"]
    argv += ["--device", "cpu", "--progress", "false", "--run-dir", str(tmp_path / "run")]
    assert pd_train.main([*argv, "--max-updates", "32"]) == 0
    assert pd_train.main(["--resume", str(tmp_path / "run"), "--max-updates", "64"]) == 0
    assert capsys.readouterr().out.splitlines().count("updates: 64") == 1


def test_options_beyond_table_2_are_refused_in_one_line(tmp_path):
    assert device_loop_unsupported(preset("paper-agent1")) == ""
    assert "double_dqn" in device_loop_unsupported(replace(preset("paper-agent1"), double_dqn=True))
    with pytest.raises(ValueError, match="n_step must be 1"):
        DeviceLoop([_cfg(tmp_path, "x", n_step=3)])
    with pytest.raises(ValueError, match="share lr"):
        DeviceLoop([_cfg(tmp_path, "x"), _cfg(tmp_path, "y", seed=4, lr=1e-4)])
    # auto: the reference loop on the CPU, and for anything beyond Table 2
    assert not uses_device_loop(preset("paper-agent1", device="cpu"))
    assert uses_device_loop(preset("paper-agent1", device="cpu", loop="device"))
    assert not uses_device_loop(preset("best", device="auto"))


def test_pd_train_trains_two_agents_together_each_in_its_folder(tmp_path, capsys):
    argv = ["--preset", "paper-agent1", "--agents", "paper-agent2:2", "--loop", "device"]
    argv += ["--num-envs", "16", "--updates-per-step", "16", "--learning-starts", "208"]
    argv += ["--max-updates", "64", "--eval-every-s", "0", "--device", "cpu"]
    argv += ["--progress", "false", "--run-dir", str(tmp_path / "run")]
    assert pd_train.main(argv) == 0
    for name in ("paper-agent1__1", "paper-agent2__2"):
        assert (tmp_path / "run" / name / "final.pt").exists()
        assert (tmp_path / "run" / name / "curves.png").exists()
    assert capsys.readouterr().out.count("updates: 64") == 2


@needs_cuda
def test_a_captured_block_is_the_eager_block_on_the_gpu(tmp_path):
    loops = []
    for graph in (True, False):
        loop = DeviceLoop([_cfg(tmp_path, f"g{graph}", device="cuda")], host_indices=True)
        loop.graph = graph  # before the first block: eager or captured
        loop._block.graph = graph
        loop.run()
        loops.append(loop)
    diff = _q(loops[0].q.network(0)) - _q(loops[1].q.network(0))
    assert diff.abs().max() < TOLERANCE


@needs_cuda
def test_a_gpu_run_with_the_reference_draws_is_the_cpu_run(tmp_path):
    cpu = DeviceLoop([_cfg(tmp_path, "cpu")], host_indices=True)
    cpu.run()
    gpu = DeviceLoop([_cfg(tmp_path, "gpu", device="cuda")], host_indices=True, overlap=False)
    gpu.run()
    assert (_q(gpu.q.network(0)) - _q(cpu.q.network(0))).abs().max() < 1e-4
    assert np.isfinite(gpu.last_diff.cpu().numpy()).all()
