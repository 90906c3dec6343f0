"""Training speed on this machine, side by side in one run.

    python bench/train_speed.py [--threads 1] [--seconds 3]

1. The paper's gradient update (7-300-200-300-147 tanh, RMSProp, 100 agent + 100 demonstration
   samples, Table 2): our `DQNAgent.update` fed by our replay memories, beside a minimal plain-torch
   loop of the same update on fixed tensors, with the GFLOP/s each achieves against a large matmul.
2. What one env step of the paper's loop (`pd-train --preset paper-agent1`, one env) costs besides
   the update: epsilon-greedy action, env step, n-step collector, replay insert, minibatch sampling,
   so the per-step cost of any `--updates-per-step` ratio can be read off.
3. Env throughput, other presets' updates/s, and `Policy.act` latency.
"""

from __future__ import annotations

import argparse
import copy
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from pd_core.dqn.agent import DQNAgent, concat_samples
from pd_core.dqn.config import preset
from pd_core.dqn.network import QNetwork
from pd_core.dqn.replay import DemoMemory, NStepCollector, ReplayMemory
from pd_core.env import make_vector_env
from pd_core.policy import load_policy, save_policy


def _timed(fn, seconds: float) -> tuple[int, float]:
    fn()  # warm-up
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        fn()
        n += 1
    return n, time.perf_counter() - t0


def _per_s(fn, seconds: float) -> float:
    n, dt = _timed(fn, seconds)
    return n / dt


def update_flops(hidden: tuple[int, ...], batch: int, n_in: int = 7, n_out: int = 147) -> float:
    """FLOPs of one DQN update: forward + backward (2x forward) of the online network on the
    batch, plus the target network's forward on the next states (multiply-add = 2 FLOPs)."""
    widths = (n_in, *hidden, n_out)
    fwd = 2.0 * batch * sum(a * b for a, b in zip(widths[:-1], widths[1:], strict=True))
    return 3.0 * fwd + fwd


def matmul_gflops(seconds: float, n: int = 2048) -> float:
    a, b = torch.randn(n, n), torch.randn(n, n)
    return _per_s(lambda: a @ b, seconds) * 2.0 * n**3 / 1e9


def _memories(rng: np.random.Generator) -> tuple[ReplayMemory, DemoMemory]:
    mem, obs = ReplayMemory(20_000), rng.normal(size=(20_000, 7)).astype(np.float32)
    mem.add(obs, rng.integers(0, 147, 20_000), rng.normal(size=20_000), obs, np.full(20_000, 0.9))
    demo = DemoMemory.fill(
        obs[:5000], rng.integers(0, 147, 5000), np.zeros(5000), obs[:5000], np.zeros(5000)
    )
    return mem, demo


def ours_updates_per_s(name: str, seconds: float, **kw) -> float:
    """`DQNAgent.update` on minibatches sampled from our replay memories, as `pd-train` does."""
    cfg = replace(preset(name), **kw)
    agent = DQNAgent(cfg)
    rng = np.random.default_rng(0)
    mem, demo = _memories(rng)

    def upd() -> None:
        b = mem.sample(cfg.batch_agent, rng)
        if cfg.batch_demo:
            b = concat_samples(b, demo.sample(cfg.batch_demo, rng))
        agent.update(b)

    return _per_s(upd, seconds)


def minimal_updates_per_s(seconds: float, batch: int = 200) -> float:
    """The same update in plain torch on fixed tensors: the floor our loop is measured against."""
    torch.manual_seed(0)
    q = QNetwork()
    qt = copy.deepcopy(q)
    opt = torch.optim.RMSprop(q.parameters(), lr=1e-5)
    obs, nobs = torch.randn(batch, 7), torch.randn(batch, 7)
    a, r, d = torch.randint(0, 147, (batch,)), torch.randn(batch), torch.rand(batch)

    def upd() -> None:
        qa = q(obs).gather(1, a[:, None]).squeeze(1)
        with torch.no_grad():
            tgt = r + d * qt(nobs).max(1).values
        loss = F.mse_loss(qa, tgt)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()

    return _per_s(upd, seconds)


def loop_costs_us(seconds: float) -> dict[str, float]:
    """Microseconds per call of each piece of the paper preset's loop (one env)."""
    cfg = preset("paper-agent1")
    agent = DQNAgent(cfg)
    rng = np.random.default_rng(0)
    mem, demo = _memories(rng)
    env = make_vector_env(1)
    obs, _ = env.reset(seed=0)
    col = NStepCollector(1, cfg.n_step, cfg.gamma)
    acts = rng.integers(0, 147, size=(1,))
    out: dict[str, float] = {}

    def step() -> None:
        nonlocal obs
        nobs, r, term, trunc, info = env.step(acts)
        obs = nobs

    pieces = {
        "act (epsilon-greedy, 1 state, eps 0.3)": lambda: agent.act(obs, 0.3, rng),
        "env.step (vector env, 1 env)": step,
        "n-step collector": lambda: col.step(
            obs, acts, np.zeros(1), obs, np.zeros(1, bool), np.zeros(1, bool), None
        ),
        "replay add (1 transition)": lambda: mem.add(obs, acts, np.zeros(1), obs, np.ones(1)),
        "sample 100 + 100 demo": lambda: concat_samples(
            mem.sample(100, rng), demo.sample(100, rng)
        ),
    }
    for name, fn in pieces.items():
        n, dt = _timed(fn, seconds)
        out[name] = 1e6 * dt / n
    return out


def act_time_us(seconds: float) -> tuple[float, float, float, float, float]:
    """Policy.act through numpy, the same behind the shield (a Table 3 state; a wide-box corner
    state the shield hands to the teacher), Policy.act_online predicting through two steps of
    identified delay (pd_core.latency) from the navigation filter's estimate (pd_core.navfilter),
    torch forward+argmax."""
    torch.manual_seed(0)
    with tempfile.TemporaryDirectory() as d:
        path = save_policy(Path(d) / "m", QNetwork())
        pol = load_policy(path)
        shielded = load_policy(path, shield="always")
    s = np.array([800.0, 100.0, 2500.0, -40.0, 10.0, -80.0, 2000.0])
    n, dt = _timed(lambda: pol.act(s), seconds)
    k, dt_sh = _timed(lambda: shielded.act(s), seconds)
    corner = np.array([0.0, -1800.0, 300.0, 0.0, -40.0, -40.0, 1800.0])
    j, dt_ho = _timed(lambda: shielded.act(corner), seconds)
    shielded.latency.delay_steps[0] = 2
    shielded.latency.margin = np.inf  # keep the lag at 2 whatever the residuals say
    i, dt_lat = _timed(lambda: shielded.act_online(s), seconds)
    net = pol.network
    x = torch.from_numpy((s * 1.0).astype(np.float32))[None]

    def torch_act() -> None:
        with torch.no_grad():
            net(x).argmax()

    m, dt2 = _timed(torch_act, seconds)
    return 1e6 * dt / n, 1e6 * dt_sh / k, 1e6 * dt_ho / j, 1e6 * dt_lat / i, 1e6 * dt2 / m


def env_steps_per_s(num_envs: int, seconds: float) -> float:
    env = make_vector_env(num_envs)
    env.reset(seed=0)
    acts = np.random.default_rng(0).integers(0, 147, size=(64, num_envs))
    i = [0]

    def step() -> None:
        env.step(acts[i[0] % 64])
        i[0] += 1

    return _per_s(step, seconds) * num_envs


def paper_update_report(seconds: float) -> float:
    """Part 1; returns the update time in microseconds (ours)."""
    flops = update_flops(preset("paper-agent1").hidden, 200)
    peak = matmul_gflops(seconds)
    ours = ours_updates_per_s("paper-agent1", seconds)
    floor = minimal_updates_per_s(seconds)
    print("1. The paper's update (batch 100 + 100, 7-300-200-300-147 tanh, RMSProp)")
    print(f"   {'':34s} {'updates/s':>10s} {'GFLOP/s':>8s} {'of matmul':>10s}")
    for name, ups in (("pd-train (DQNAgent + replay)", ours), ("minimal plain-torch loop", floor)):
        g = ups * flops / 1e9
        print(f"   {name:34s} {ups:10.1f} {g:8.1f} {g / peak:9.0%}")
    print(f"   {'2048x2048 matmul':34s} {'':10s} {peak:8.1f} {1:9.0%}")
    print(f"   ours / minimal: {ours / floor:.2f}; {flops / 1e6:.0f} MFLOP per update")
    return 1e6 / ours


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--threads", type=int, default=1, help="torch threads (default 1)")
    ap.add_argument("--seconds", type=float, default=3.0, help="seconds per figure (default 3)")
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    print(f"torch threads: {a.threads}")
    upd_us = paper_update_report(a.seconds)
    costs = loop_costs_us(a.seconds)
    print("2. One env step of the paper's loop besides the update (us per call)")
    for name, us in costs.items():
        print(f"   {name:42s} {us:9.1f}")
    per_step = sum(v for k, v in costs.items() if not k.startswith("sample"))
    sample = costs["sample 100 + 100 demo"]
    print(f"   {'per env step without updates':42s} {per_step:9.1f}")
    for ratio in (1.0, 0.25, 0.125):
        total = per_step + ratio * (upd_us + sample)
        share = ratio * (upd_us + sample) / total
        print(
            f"   --updates-per-step {ratio:<5}: {total:8.0f} us per env step "
            f"({1e6 / total:6.0f} steps/s), updates {share:.0%} of it"
        )
    print("3. Other figures")
    for n in (1, 32, 4096):
        print(f"   env steps/s, vector env, {n:5d} envs: {env_steps_per_s(n, a.seconds):12.0f}")
    for name, kw in (("paper-agent2", {}), ("best", {})):
        cfg = replace(preset(name), **kw)
        ups = ours_updates_per_s(name, a.seconds, **kw)
        print(f"   updates/s, {name:12s} batch {cfg.batch_agent}+{cfg.batch_demo}: {ups:8.1f}")
    us, ussh, usho, uslat, ust = act_time_us(a.seconds)
    print(
        f"   Policy.act(one state): numpy {us:.1f} us; behind the shield {ussh:.1f} us "
        f"({ussh / us:.2f}x), {usho:.1f} us ({usho / us:.2f}x) where it hands over to the "
        f"teacher; act_online (navigation filter, 2 steps of identified delay) {uslat:.1f} us "
        f"({uslat / us:.2f}x); torch forward+argmax {ust:.1f} us"
    )


if __name__ == "__main__":
    main()
