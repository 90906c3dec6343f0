"""Receding-horizon teacher (pd_core.teachers.mpc): per-step re-plan time beside a cold
free-final-time
solve, and closed-loop success and fuel beside ZEM/ZEV, in one run.

Part 1 flies `--episodes` nominal Table 3 episodes (disturbances on, seed `--seed`) with mpc-fuel,
mpc-energy and zemzev, and prints per controller: success, median fuel, fuel / fuel-optimal
(`pd_core.ocp.solve(objective="fuel")` with the RL limits from each initial state, the first
`--fuel-subset` episodes), the warm re-plan time (median, p99; wall clock and CPU time of the
solving thread) and the CPU time of the cold free-t_f solve of each episode's first state, with
their ratio (CPU). On a machine other processes load, wall clock includes waiting for a core;
CPU time does not.

Part 2 (`--lp`): the fuel LP of a warm re-plan through scipy's linprog(method="highs") against
highspy directly (no presolve), on the same LPs.

Part 3 (`--demos N`): wall time of N teacher demonstration episodes
(`pd_core.demonstrations.teacher_flown.controller_demonstrations`, mpc-fuel, every core, under
`--dispersions`)
and the time it implies for 1000 (issue 10 asks <= 10 min on this 2-core machine).

Single-threaded BLAS (set below before numpy loads), as bench/ocp_speed.py.
"""

from __future__ import annotations

import argparse
import os
import time
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from scipy.optimize import linprog  # noqa: E402

from pd_core import ocp  # noqa: E402
from pd_core.config import RL_THRUST  # noqa: E402
from pd_core.demonstrations.teacher_flown import controller_demonstrations  # noqa: E402
from pd_core.experiments.evaluate import rollout  # noqa: E402
from pd_core.ocp.fuel import fuel_weights, new_highs, solve_lp  # noqa: E402
from pd_core.ocp.model import KN  # noqa: E402
from pd_core.teachers.mpc import MPCController, MPCParams  # noqa: E402
from pd_core.teachers.registry import make_controller  # noqa: E402
from pd_core.teachers.zemzev import ZemZevController  # noqa: E402


def _ms(v: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(v) * 1e3, q)) if v else float("nan")


def controller(name: str) -> Any:
    """A registered controller, or `mpc-<objective>-nearest`: the teacher rounding to the
    nearest level instead of Eq. 5 (not the paper's; for comparison)."""
    if name.endswith("-nearest"):
        objective = name.split("-")[1]
        return MPCController(MPCParams(objective=objective, rounding="nearest"), ZemZevController())
    return make_controller(name)


def fly(name: str, episodes: int, seed: int, fuel_opt: np.ndarray) -> dict[str, float]:
    ctl = controller(name)
    t0 = time.perf_counter()
    ro = rollout(ctl, episodes, seed)
    wall = time.perf_counter() - t0
    k = len(fuel_opt)
    out = {
        "success": float(np.mean(ro.landed)),
        "fuel": float(np.median(ro.fuel_kg)),
        "ratio": float(np.median(ro.fuel_kg[:k] / fuel_opt)) if k else float("nan"),
        "wall_s": wall,
        "steps": int(ro.steps.sum()),
    }
    if isinstance(ctl, MPCController):
        st = ctl.stats
        out |= {
            "warm_med": _ms(st.warm, 50),
            "warm_p99": _ms(st.warm, 99),
            "warm_cpu_med": _ms(st.warm_cpu, 50),
            "warm_cpu_p99": _ms(st.warm_cpu, 99),
            "cold_med": _ms(st.cold, 50),
            "cold_cpu_med": _ms(st.cold_cpu, 50),
            "fallback_pct": 100.0 * st.fallback_steps / max(out["steps"], 1),
        }
    return out


def fuel_optimal(
    episodes: int, seed: int, subset: int
) -> tuple[np.ndarray, list[float], list[float]]:
    """Fuel-optimal fuel (kg) from the first `subset` initial states, and each solve's wall
    and CPU time (s)."""
    init = rollout(make_controller("zemzev"), min(subset, episodes), seed).initial_states
    fuel, wall, cpu = [], [], []
    for s in init:
        c0 = time.thread_time()
        r = ocp.solve(s[0:3], s[3:6], s[6], objective="fuel", limits=RL_THRUST)
        cpu.append(time.thread_time() - c0)
        fuel.append(r.fuel)
        wall.append(r.solve_time)
    return np.array(fuel), wall, cpu


def lp_compare(n_control: int = 40, repeats: int = 30) -> tuple[float, float]:
    """Median ms of one warm-re-plan fuel LP: scipy linprog vs highspy (no presolve)."""
    s = np.array([800.0, -400.0, 1200.0, -30.0, 10.0, -60.0, 1900.0])
    r = ocp.solve(s[0:3], s[3:6], s[6], objective="fuel", limits=RL_THRUST, n_control=n_control)
    pb = ocp.Problem(s[0:3], s[3:6], s[6], "fuel", n_control, RL_THRUST)
    g = pb.grid(r.time_of_flight)
    jac, rhs, _ = pb.linearised(r.thrust, g)
    c = np.tile(fuel_weights(g), 6)
    a_eq = np.concatenate([jac, -jac], axis=2).reshape(6, 6 * n_control)
    hi_pm = np.stack([np.maximum(pb.limits.hi, 0.0), np.maximum(-pb.limits.lo, 0.0)], 1) / KN
    ub = np.repeat(hi_pm.reshape(-1), n_control)
    lb = np.zeros_like(ub)
    h = new_highs()
    t_scipy, t_hs = [], []
    for _ in range(repeats):
        t0 = time.thread_time()
        linprog(c, A_eq=a_eq, b_eq=rhs, bounds=np.stack([lb, ub], 1), method="highs")
        t_scipy.append(time.thread_time() - t0)
        t0 = time.thread_time()
        solve_lp(c, a_eq, rhs, lb, ub, h)
        t_hs.append(time.thread_time() - t0)
    return _ms(t_scipy, 50), _ms(t_hs, 50)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--episodes", type=int, default=200)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--fuel-subset", type=int, default=50, help="fuel-optimal solves (slow)")
    ap.add_argument(
        "--controllers",
        nargs="+",
        default=["mpc-fuel", "mpc-energy", "zemzev"],
        help="registered names, or mpc-fuel-nearest / mpc-energy-nearest",
    )
    ap.add_argument("--lp", action="store_true", help="also compare scipy linprog and highspy")
    ap.add_argument("--demos", type=int, default=0, metavar="N", help="time N demo episodes")
    ap.add_argument("--dispersions", default="standard", help="dispersions of the demo episodes")
    ap.add_argument("--only-demos", action="store_true", help="skip parts 1 and 2")
    args = ap.parse_args(argv)
    if args.demos > 0:
        t0 = time.perf_counter()
        d = controller_demonstrations(
            "mpc-fuel", args.demos, args.seed, dispersions=args.dispersions
        )
        wall = time.perf_counter() - t0
        print(
            f"{args.demos} mpc-fuel demonstration episodes ({args.dispersions}, {os.cpu_count()} "
            f"workers): {wall:.0f} s wall, {len(d['actions'])} transitions, success "
            f"{100 * float(d['success_rate']):.1f} %; 1000 episodes -> "
            f"{1000 * wall / args.demos / 60:.1f} min"
        )
        if args.only_demos:
            return 0
    fuel_opt, opt_wall, opt_cpu = fuel_optimal(args.episodes, args.seed, args.fuel_subset)
    print(
        f"{args.episodes} nominal Table 3 episodes (disturbances on, seed {args.seed}); fuel "
        f"ratio over the first {len(fuel_opt)}; cold free-t_f fuel-optimal solve (80 points) "
        f"median {_ms(opt_wall, 50):.1f} ms wall, {_ms(opt_cpu, 50):.1f} ms CPU"
    )
    head = (
        f"{'controller':<11}{'success':>8}{'fuel kg':>9}{'/opt':>7}{'warm ms med/p99':>17}"
        f"{'cpu ms med/p99':>16}{'cold cpu':>9}{'cold/warm':>10}{'fallback%':>10}{'wall s':>8}"
    )
    print(head)
    for name in args.controllers:
        r = fly(name, args.episodes, args.seed, fuel_opt)
        row = f"{name:<11}{100 * r['success']:>7.1f}%{r['fuel']:>9.1f}{r['ratio']:>7.3f}"
        if "warm_med" in r:
            row += (
                f"{r['warm_med']:>9.2f}/{r['warm_p99']:<7.1f}"
                f"{r['warm_cpu_med']:>8.2f}/{r['warm_cpu_p99']:<7.1f}{r['cold_cpu_med']:>9.1f}"
                f"{r['cold_cpu_med'] / r['warm_cpu_med']:>9.0f}x{r['fallback_pct']:>10.1f}"
            )
        else:
            row += f"{'-':>17}{'-':>16}{'-':>9}{'-':>10}{'-':>10}"  # a law, no solves
        print(row + f"{r['wall_s']:>8.1f}", flush=True)
    if args.lp:
        sp, hs = lp_compare()
        print(f"fuel LP of a re-plan (40 points, CPU ms): scipy linprog {sp:.2f}, highspy {hs:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
