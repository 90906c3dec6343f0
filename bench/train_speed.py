"""Training speed on this machine: env steps/s, gradient updates/s, and act() decision time.

    python bench/train_speed.py [--threads 1] [--seconds 5]

Prints one line per figure; every figure is measured with torch.set_num_threads(--threads).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from pd_core.dqn.agent import DQNAgent, concat_samples
from pd_core.dqn.config import preset
from pd_core.dqn.network import QNetwork
from pd_core.dqn.replay import DemoMemory, ReplayMemory
from pd_core.dqn.train import make_vector_env
from pd_core.policy import load_policy, save_policy


def _timed(fn, seconds: float) -> tuple[int, float]:
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        fn()
        n += 1
    return n, time.perf_counter() - t0


def env_steps_per_s(num_envs: int, seconds: float) -> float:
    env = make_vector_env(num_envs)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    acts = rng.integers(0, 147, size=(64, num_envs))
    i = [0]

    def step() -> None:
        env.step(acts[i[0] % 64])
        i[0] += 1

    n, dt = _timed(step, seconds)
    return n * num_envs / dt


def updates_per_s(name: str, seconds: float, **kw) -> float:
    cfg = replace(preset(name), **kw)
    agent = DQNAgent(cfg)
    rng = np.random.default_rng(0)
    mem, obs = ReplayMemory(20_000), rng.normal(size=(20_000, 7)).astype(np.float32)
    mem.add(obs, rng.integers(0, 147, 20_000), rng.normal(size=20_000), obs, np.full(20_000, 0.9))
    demo = DemoMemory.fill(
        obs[:5000], rng.integers(0, 147, 5000), np.zeros(5000), obs[:5000], np.zeros(5000)
    )

    def upd() -> None:
        b = mem.sample(cfg.batch_agent, rng)
        if cfg.batch_demo:
            b = concat_samples(b, demo.sample(cfg.batch_demo, rng))
        agent.update(b)

    n, dt = _timed(upd, seconds)
    return n / dt


def act_time_us(seconds: float) -> tuple[float, float]:
    torch.manual_seed(0)
    with tempfile.TemporaryDirectory() as d:
        path = save_policy(Path(d) / "m", QNetwork())
        pol = load_policy(path)
    s = np.array([800.0, 100.0, 2500.0, -40.0, 10.0, -80.0, 2000.0])
    n, dt = _timed(lambda: pol.act(s), seconds)
    net = pol.network
    x = torch.from_numpy((s * 1.0).astype(np.float32))[None]

    def torch_act() -> None:
        with torch.no_grad():
            net(x).argmax()

    m, dt2 = _timed(torch_act, seconds)
    return 1e6 * dt / n, 1e6 * dt2 / m


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--seconds", type=float, default=3.0)
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    print(f"torch threads: {a.threads}, cores seen: {torch.get_num_threads()}")
    for n in (1, 32, 4096):
        print(
            f"env steps/s, vector env, {n:5d} envs, random actions: "
            f"{env_steps_per_s(n, a.seconds):12.0f}"
        )
    rows = [
        ("paper-agent1", {}),
        ("paper-agent2", {}),
        ("best", {}),
        ("best", {"batch_agent": 256, "batch_demo": 256}),
    ]
    for name, kw in rows:
        cfg = replace(preset(name), **kw)
        print(
            f"gradient updates/s, {name:12s} batch {cfg.batch_agent}+{cfg.batch_demo}"
            f"{' double' if cfg.double_dqn else ''}: {updates_per_s(name, a.seconds, **kw):8.1f}"
        )
    us, ust = act_time_us(a.seconds)
    print(f"Policy.act(one state), numpy path: {us:8.1f} us; torch forward+argmax: {ust:8.1f} us")


if __name__ == "__main__":
    main()
