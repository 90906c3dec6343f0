"""What a decision costs: the shipped file behind its runtime layer beside the bare network and
ZEM/ZEV, per decision and per campaign, side by side in one run, with the ratios.

1. One decision of one lander (`Runtime.step`, the policy node's call) with the full layer,
   median and p99 over a flown nominal episode replayed many times in `--rounds` rounds that
   interleave the agents (and the spread of the rounds' medians), beside a bare float32
   forward of the same network (`NumpyQNetwork.act_batch` on one state), ZEM/ZEV and the
   optimal-control teacher `mpc-fuel-reserve` behind the same layer (a warm re-plan a step).
2. A one-process nominal campaign (`pd_core.experiments.campaign.run_campaign`, 1024 landers
   per batch) in episodes/min: the shipped file, its bare network, ZEM/ZEV.

BLAS and numba are held to one thread: "one process" is one core. The first line says which
implementation ran (the layer's compiled kernels, `pd_core.runtime.kernels`, and the network's
forward) and what loading the file cost (weights, and the kernels from numba's cache or compiled).

    python bench/runtime_speed.py [--episodes 4096] [--decisions 5000] [--rounds 5]
                                  [--policy FILE.pt]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: one process = one core
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import argparse  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from pd_core.dispersions import NOMINAL  # noqa: E402
from pd_core.episodes import rollout  # noqa: E402
from pd_core.experiments.campaign import metrics, run_campaign  # noqa: E402
from pd_core.runtime.build import build  # noqa: E402
from pd_core.runtime.layer import Runtime  # noqa: E402
from pd_core.runtime.policy_file import SHIPPED_POLICY  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / SHIPPED_POLICY


def per_decision_us(call, states: np.ndarray, repeats: int) -> np.ndarray:
    """Microseconds of each call(state) over `states`, flown `repeats` times in order."""
    out = []
    for _ in range(repeats):
        for s in states:
            t0 = time.perf_counter()
            call(s)
            out.append(time.perf_counter() - t0)
    return 1e6 * np.array(out)


def implementation(rt: Runtime, load_s: float) -> str:
    """One line: what runs a decision, and what loading the policy file took."""
    net = type(rt.actor).__name__ + f" {getattr(rt.actor, 'dtype', '')}".rstrip()
    try:
        import numba  # noqa: PLC0415  (imported by the layer already)

        from pd_core.runtime import (  # noqa: PLC0415
            kernels,
            kernels_latency,
            kernels_nav,
            kernels_rules,
            kernels_step,
        )
    except ImportError:  # a tree from before the kernels
        layer = "runtime layer numpy"
    else:
        compiled = sorted(
            name
            for module in (kernels, kernels_latency, kernels_nav, kernels_rules, kernels_step)
            for name, f in vars(module).items()
            if getattr(f, "signatures", None)
        )
        layer = f"runtime layer numba {numba.__version__} kernels ({', '.join(compiled)})"
    return (
        f"implementation: {layer}, network {net} (numpy {np.__version__}); "
        f"load_policy {load_s:.2f} s (weights, and any kernels compiled or from numba's cache)"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--episodes", type=int, default=4096, help="campaign episodes per agent")
    ap.add_argument("--decisions", type=int, default=5000, help="timed single decisions")
    ap.add_argument("--rounds", type=int, default=5, help="interleaved rounds of the decisions")
    ap.add_argument("--policy", default=str(SHIPPED), help="policy file (default: the shipped one)")
    args = ap.parse_args()
    policy = Path(args.policy)

    t0 = time.perf_counter()
    rt = build(policy).runtime
    load_s = time.perf_counter() - t0
    print(implementation(rt, load_s) + "\n")
    path = rollout(rt, 1, 0, keep_trajectories=1).trajectories[0][:-1]  # one nominal flight
    repeats = max(1, args.decisions // (len(path) * args.rounds))
    zz = build("controller:zemzev-vernier", as_runtime=True).runtime
    teacher = build("layer:controller:mpc-fuel-reserve").runtime

    def layer_step(s: np.ndarray) -> None:
        rt.step(s)

    def episode_start() -> None:
        rt.begin_episode()

    episode_start()
    per_decision_us(layer_step, path[:20], 1)  # warm-up (and any compilation)
    calls = (
        (f"{policy.stem}, full runtime layer (Runtime.step)", layer_step),
        ("bare float32 forward (NumpyQNetwork, 1 state)", lambda s: rt.actor.act_batch(s[None])),
        ("ZEM/ZEV-vernier (1 state)", lambda s: zz.step(s)),
    )
    # rounds interleave the agents, so a machine that slows down for a minute slows all of
    # them: each round flies the path `repeats` times per agent; the spread of the rounds'
    # medians says how steady the machine was
    timings: dict[str, list[np.ndarray]] = {name: [] for name, _ in calls}
    for _ in range(args.rounds):
        for name, call in calls:
            episode_start()
            timings[name].append(per_decision_us(call, path, repeats))
    # the optimal-control teacher re-plans every step: one pass of the flight (its first
    # decision is a cold solve, in the p99)
    teacher.begin_episode()
    timings["mpc-fuel-reserve teacher, full runtime layer"] = [
        per_decision_us(lambda s: teacher.step(s), path, 1)
    ]
    base = np.median(np.concatenate(timings["bare float32 forward (NumpyQNetwork, 1 state)"]))
    print(f"one decision (one core; {args.rounds} rounds, agents interleaved):")
    head = f"  {'':<52}{'calls':>7}{'median us':>10}{'p99 us':>10}{'x bare':>9}"
    print(head + f"{'rounds us':>16}")
    for name, parts in timings.items():
        t = np.concatenate(parts)
        med, p99 = np.median(t), np.percentile(t, 99)
        per_round = [np.median(p) for p in parts]
        spread = f"{min(per_round):.0f}-{max(per_round):.0f}" if len(parts) > 1 else "-"
        print(f"  {name:<52}{len(t):>7}{med:>10.1f}{p99:>10.1f}{med / base:>9.1f}{spread:>16}")

    print(f"\none-process nominal campaign, {args.episodes} episodes per agent:")
    print(f"  {'':<52}{'episodes/min':>13}{'success %':>11}{'x ZEM/ZEV':>11}")
    rates = {}
    for name, spec in (
        (f"{policy.stem} behind its runtime layer", str(policy)),
        ("its bare network", f"bare:{policy}"),
        ("ZEM/ZEV-vernier", "controller:zemzev-vernier"),
    ):
        t0 = time.perf_counter()
        flown = run_campaign({"a": spec}, [NOMINAL], args.episodes, seed=0)
        dt = time.perf_counter() - t0
        rates[name] = (60.0 * args.episodes / dt, metrics(flown["nominal"]["a"])["success_rate"])
    zz_rate = rates["ZEM/ZEV-vernier"][0]
    for name, (rate, ok) in rates.items():
        print(f"  {name:<52}{rate:>13,.0f}{100 * ok:>11.2f}{rate / zz_rate:>11.2f}")


if __name__ == "__main__":
    main()
