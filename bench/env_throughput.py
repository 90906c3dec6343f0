"""Environment throughput: single-env steps/s and vector-env steps/s for batch sizes 1..4096.

Prints one table with the issue's targets beside the figures (>= 2 M env-steps/s batched,
<= 20 us per single-env step). Random actions, disturbances on, autoreset on; and the
batched rate under every dispersion at once (scenario `all`).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from pd_core.dispersions import load_scenarios
from pd_core.env import PoweredDescentEnv
from pd_core.vector_env import PoweredDescentVectorEnv


def single_env_us_per_step(n_steps: int, seed: int) -> float:
    env = PoweredDescentEnv()
    env.reset(seed=seed)
    actions = np.random.default_rng(seed).integers(0, 147, n_steps).tolist()
    t0 = time.perf_counter()
    for a in actions:
        _, _, term, trunc, _ = env.step(a)
        if term or trunc:
            env.reset()
    return (time.perf_counter() - t0) / n_steps * 1e6


def vector_steps_per_s(
    batch: int, min_env_steps: int, seed: int, dispersions: str = "nominal"
) -> float:
    venv = PoweredDescentVectorEnv(batch, dispersions=load_scenarios(dispersions))
    venv.reset(seed=seed)
    rng = np.random.default_rng(seed)
    n_calls = max(20, min_env_steps // batch)
    actions = rng.integers(0, 147, (n_calls, batch))
    venv.step(actions[0])  # warm-up
    t0 = time.perf_counter()
    for a in actions:
        venv.step(a)
    return n_calls * batch / (time.perf_counter() - t0)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--steps", type=int, default=400_000, help="env-steps per measurement")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--repeats", type=int, default=3, help="best of N repeats is reported")
    args = parser.parse_args(argv)

    us = min(single_env_us_per_step(args.steps // 4, args.seed) for _ in range(args.repeats))
    print(
        f"single env (PoweredDescentEnv.step):  {us:6.2f} us/step  = {1e6 / us:>12,.0f} steps/s"
        f"   target <= 20 us: {'met' if us <= 20 else 'MISSED'}"
    )
    print()
    print(f"{'batch':>6} {'env-steps/s':>14} {'x single env':>13}")
    best = 0.0
    for b in (1, 4, 16, 64, 256, 1024, 4096):
        sps = max(vector_steps_per_s(b, args.steps, args.seed) for _ in range(args.repeats))
        best = max(best, sps)
        print(f"{b:>6} {sps:>14,.0f} {sps * us / 1e6:>13.1f}")
    print(
        f"\nbest batched: {best:,.0f} env-steps/s   target >= 2,000,000: "
        f"{'met' if best >= 2e6 else 'MISSED'}"
    )
    disp = max(vector_steps_per_s(1024, args.steps, args.seed, "all") for _ in range(args.repeats))
    print(
        f"batch 1024 under every dispersion at once (scenario 'all'): {disp:,.0f} env-steps/s "
        f"({disp / best:.2f}x the best nominal)"
    )


if __name__ == "__main__":
    main()
