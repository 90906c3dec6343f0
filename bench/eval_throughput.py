"""Campaign throughput: episodes/min of a nominal campaign, one process against Ray, side by side.

For the shipped DQN (models/pd_dqn_best.pt) and the ZEM/ZEV controller: the same N-episode
nominal campaign (seed 0, episode i on seed i) flown in one process and as Ray tasks on a local
Ray instance with --ray-cpus CPUs, the ratio (target >= 1.7x on 2 cores), and a check that both
gave the same numbers. BLAS is held to one thread, so "one process" is one core.

Then a profile of the one-process path on one chunk (1024 episodes flown as one batch): time in
the batched forward pass (`act_batch`) against the env step, each against what this CPU can do
(dgemm peak of one core for the forward pass; the per-call overhead of a batch-of-1 step for
the env step, which is numpy dispatch, not arithmetic).

    python bench/eval_throughput.py                       # 100,000 episodes per agent (slow)
    python bench/eval_throughput.py --episodes 10000      # a quick look
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: one process = one core
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from pd_core.dispersions import NOMINAL  # noqa: E402
from pd_core.episodes import CHUNK_EPISODES, fly_episodes  # noqa: E402
from pd_core.experiments.campaign import metrics, run_campaign  # noqa: E402
from pd_core.runtime.build import build  # noqa: E402
from pd_core.vector_env import make_vector_env  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def one_process(spec: str, episodes: int) -> tuple[float, dict]:
    t0 = time.perf_counter()
    flown = run_campaign({"a": spec}, [NOMINAL], episodes, seed=0)
    return time.perf_counter() - t0, metrics(flown["nominal"]["a"])


def on_ray(spec: str, episodes: int) -> tuple[float, dict]:
    from pd_core.experiments.ray_campaign import run_campaign_ray  # Ray only for this half

    t0 = time.perf_counter()
    flown = run_campaign_ray({"a": spec}, [NOMINAL], episodes, seed=0, progress=False)
    return time.perf_counter() - t0, metrics(flown["nominal"]["a"])


class Timed:
    """Wraps an actor and an env to add up the time spent in each."""

    def __init__(self, actor, env) -> None:
        self.actor, self.env, self.t_act, self.t_env, self.rows, self.calls = actor, env, 0, 0, 0, 0
        self.num_envs = env.num_envs

    def act_batch(self, s: np.ndarray) -> np.ndarray:
        t0 = time.perf_counter()
        a = self.actor.act_batch(s)
        self.t_act += time.perf_counter() - t0
        self.rows += len(s)
        return a

    def __getattr__(self, name):  # the env's reset/active pass through
        return getattr(self.env, name)

    def step(self, a):
        t0 = time.perf_counter()
        out = self.env.step(a)
        self.t_env += time.perf_counter() - t0
        self.calls += 1
        return out


def dgemm_gflops() -> float:
    a, b = np.random.default_rng(0).normal(size=(2, 1024, 1024))
    a @ b
    t0 = time.perf_counter()
    for _ in range(5):
        a @ b
    return 5 * 2 * 1024**3 / (time.perf_counter() - t0) / 1e9


def env_step_floor_us() -> float:
    """Time of one batched step of one lander: the fixed per-call cost (numpy dispatch)."""
    env = make_vector_env(1, autoreset=True)
    env.reset(seed=0)
    a = np.array([73])
    t0 = time.perf_counter()
    for _ in range(2000):
        env.step(a)
    return (time.perf_counter() - t0) / 2000 * 1e6


def profile(spec: str) -> dict:
    actor = build(spec).actor
    env = make_vector_env(CHUNK_EPISODES, autoreset=False)
    timed = Timed(actor, env)
    t0 = time.perf_counter()
    ro = fly_episodes(timed, timed, seed=0)
    total = time.perf_counter() - t0
    out = {
        "episodes": CHUNK_EPISODES,
        "wall_s": total,
        "forward_s": timed.t_act,
        "env_step_s": timed.t_env,
        "other_s": total - timed.t_act - timed.t_env,
        "batched_steps": timed.calls,
        "lander_steps": int(ro.steps.sum()),
        "env_us_per_batched_step": timed.t_env / timed.calls * 1e6,
        "env_floor_us_per_call": env_step_floor_us(),
    }
    layers = getattr(actor, "_layers", None)
    if layers:  # a Q-network: flops of its dense layers per forward row
        flops = 2 * sum(w.shape[0] * w.shape[1] for w, _ in layers)
        out["forward_gflops"] = flops * timed.rows / timed.t_act / 1e9
        out["dgemm_peak_gflops"] = dgemm_gflops()
    return out


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--episodes", type=int, default=100_000)
    p.add_argument("--model", default=str(ROOT / "models" / "pd_dqn_best.pt"))
    p.add_argument("--ray-cpus", type=int, default=2)
    p.add_argument("--json", help="also write the figures to this file")
    args = p.parse_args(argv)
    from pd_core.ray_session import connect  # Ray only for the Ray half

    agents = {"DQN (shipped)": args.model, "ZEM/ZEV": "controller:zemzev"}
    rows, profiles = {}, {}
    for name, spec in agents.items():
        t1, m1 = one_process(spec, args.episodes)
        connect(None, num_cpus=args.ray_cpus)
        on_ray(spec, min(args.episodes, 2 * CHUNK_EPISODES))  # warm the workers (torch import)
        t2, m2 = on_ray(spec, args.episodes)
        rows[name] = {
            "one_process_ep_per_min": args.episodes / t1 * 60,
            "ray_ep_per_min": args.episodes / t2 * 60,
            "ratio": t1 / t2,
            "same_numbers": m1 == m2,
            "success_rate": m1["success_rate"],
        }
        profiles[name] = profile(spec)
    print(
        f"nominal campaign of {args.episodes} episodes (seed 0); Ray: local, {args.ray_cpus} CPUs"
    )
    print(f"{'agent':<16}{'1 process ep/min':>18}{'Ray ep/min':>14}{'ratio':>8}  same numbers")
    for name, r in rows.items():
        print(
            f"{name:<16}{r['one_process_ep_per_min']:>18,.0f}{r['ray_ep_per_min']:>14,.0f}"
            f"{r['ratio']:>7.2f}x  {r['same_numbers']}   (target ratio >= 1.7)"
        )
    print("\none-process profile, one chunk of", CHUNK_EPISODES, "episodes:")
    for name, pr in profiles.items():
        line = (
            f"{name:<16} forward {pr['forward_s']:.2f} s, env step {pr['env_step_s']:.2f} s, "
            f"other {pr['other_s']:.2f} s; env {pr['env_us_per_batched_step']:.0f} us per batched "
            f"step (per-call floor {pr['env_floor_us_per_call']:.0f} us)"
        )
        if "forward_gflops" in pr:
            line += (
                f"; forward {pr['forward_gflops']:.1f} GFLOP/s of a "
                f"{pr['dgemm_peak_gflops']:.1f} GFLOP/s one-core dgemm peak"
            )
        print(line)
    if args.json:
        Path(args.json).write_text(json.dumps({"rows": rows, "profiles": profiles}, indent=2))


if __name__ == "__main__":
    main()
