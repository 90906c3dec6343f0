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

Part 2 (`--lp`): the fuel LP of a warm re-plan through scipy's linprog(method="highs"), highspy
with a `HighsLp` built in Python (the path before issue 32), and `pd_core.ocp.lp.LPSolver`
(arrays passed straight to HiGHS, one model re-used; cold, and warm from the last LP's basis),
on the same LPs; and (`--banded`) the energy QP's tridiagonal solve, scipy `solve_banded`
against LAPACK `dptsv`.

A registered controller name with `-warmlp` appended flies it with `warm_lp=True` (each fuel LP
starts from the last LP's optimal basis).

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
from dataclasses import replace
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import highspy  # noqa: E402
import numpy as np  # noqa: E402
from scipy.linalg import solve_banded  # noqa: E402
from scipy.linalg.lapack import dptsv  # noqa: E402
from scipy.optimize import linprog  # noqa: E402

from pd_core import ocp  # noqa: E402
from pd_core.config import RL_THRUST  # noqa: E402
from pd_core.demonstrations.teacher_flown import controller_demonstrations  # noqa: E402
from pd_core.episodes import rollout  # noqa: E402
from pd_core.ocp.fuel import fuel_weights  # noqa: E402
from pd_core.ocp.lp import LPSolver, new_highs  # noqa: E402
from pd_core.ocp.model import KN  # noqa: E402
from pd_core.teachers.mpc import MPCController, MPCParams  # noqa: E402
from pd_core.teachers.registry import make_controller  # noqa: E402
from pd_core.teachers.zemzev import ZemZevController  # noqa: E402


def _ms(v: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(v) * 1e3, q)) if v else float("nan")


def controller(name: str) -> Any:
    """A registered controller, `NAME-warmlp` (NAME with `warm_lp=True`), or
    `mpc-<objective>-nearest`: the teacher rounding to the nearest level instead of Eq. 5 (not
    the paper's; for comparison)."""
    if name.endswith("-warmlp"):
        base = make_controller(name[: -len("-warmlp")])
        return MPCController(replace(base.params, warm_lp=True), base.fallback)
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
    s = init[0]  # untimed: the first call loads the compiled kernels (pd_core.ocp.kernels)
    ocp.solve(s[0:3], s[3:6], s[6], objective="fuel", limits=RL_THRUST)
    fuel, wall, cpu = [], [], []
    for s in init:
        c0 = time.thread_time()
        r = ocp.solve(s[0:3], s[3:6], s[6], objective="fuel", limits=RL_THRUST)
        cpu.append(time.thread_time() - c0)
        fuel.append(r.fuel)
        wall.append(r.solve_time)
    return np.array(fuel), wall, cpu


def _old_highs_lp(c, a_eq, rhs, lb, ub, h) -> None:  # noqa: ANN001
    """The fuel LP through a `HighsLp` built in Python (solve_lp before issue 32)."""
    rows, cols = a_eq.shape
    lp = highspy.HighsLp()
    lp.num_col_, lp.num_row_ = cols, rows
    lp.col_cost_, lp.col_lower_, lp.col_upper_ = c, lb, ub
    lp.row_lower_, lp.row_upper_ = rhs, rhs
    lp.a_matrix_.format_ = highspy.MatrixFormat.kColwise
    lp.a_matrix_.start_ = np.arange(0, rows * cols + 1, rows)
    lp.a_matrix_.index_ = np.tile(np.arange(rows), cols)
    lp.a_matrix_.value_ = a_eq.T.reshape(-1)
    h.passModel(lp)
    h.run()


def lp_compare(n_control: int = 40, repeats: int = 30) -> dict[str, float]:
    """Median CPU ms of one warm-re-plan fuel LP (a sequence of nearby LPs): scipy
    linprog, highspy with a HighsLp, LPSolver cold and LPSolver warm (last LP's basis); the LPs
    are one state's at t_f growing by 0.05 s (all feasible)."""
    s = np.array([800.0, -400.0, 1200.0, -30.0, 10.0, -60.0, 1900.0])
    r = ocp.solve(s[0:3], s[3:6], s[6], objective="fuel", limits=RL_THRUST, n_control=n_control)
    pb = ocp.Problem(s[0:3], s[3:6], s[6], "fuel", n_control, RL_THRUST)
    hi_pm = np.stack([np.maximum(pb.limits.hi, 0.0), np.maximum(-pb.limits.lo, 0.0)], 1) / KN
    ub = np.repeat(hi_pm.reshape(-1), n_control)
    lb = np.zeros_like(ub)
    lps = []
    for k in range(repeats):
        g = pb.grid(r.time_of_flight + 0.05 * k)
        jac, rhs, _ = pb.linearised(r.thrust, g)
        c = np.tile(fuel_weights(g), 6)
        a_eq = np.concatenate([jac, -jac], axis=2).reshape(6, 6 * n_control)
        lps.append((c, a_eq, rhs))
    h = new_highs()
    cold, warm = LPSolver(warm=False), LPSolver(warm=True)
    times: dict[str, list[float]] = {"scipy": [], "highslp": [], "cold": [], "warm": []}
    for c, a_eq, rhs in lps:
        t0 = time.thread_time()
        linprog(c, A_eq=a_eq, b_eq=rhs, bounds=np.stack([lb, ub], 1), method="highs")
        times["scipy"].append(time.thread_time() - t0)
        t0 = time.thread_time()
        _old_highs_lp(c, a_eq, rhs, lb, ub, h)
        times["highslp"].append(time.thread_time() - t0)
        t0 = time.thread_time()
        cold.solve(c, a_eq, rhs, rhs, lb, ub)
        times["cold"].append(time.thread_time() - t0)
        t0 = time.thread_time()
        warm.solve(c, a_eq, rhs, rhs, lb, ub)
        times["warm"].append(time.thread_time() - t0)
    return {k: _ms(v, 50) for k, v in times.items()}


def banded_compare(n: int = 40, repeats: int = 2000) -> tuple[float, float]:
    """Median CPU us of one tridiagonal SPD solve with 7 right-hand sides (the energy QP's):
    scipy solve_banded against LAPACK dptsv."""
    rng = np.random.default_rng(0)
    d = 2.0 + rng.uniform(size=n)
    e = rng.uniform(-0.5, 0.5, n - 1)
    b = rng.normal(size=(n, 7))
    ab = np.zeros((3, n))
    ab[0, 1:], ab[1], ab[2, :-1] = e, d, e
    t_b, t_d = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        solve_banded((1, 1), ab, b, check_finite=False)
        t_b.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        dptsv(d, e, b)
        t_d.append(time.perf_counter() - t0)
    return 1e3 * _ms(t_b, 50), 1e3 * _ms(t_d, 50)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--episodes", type=int, default=200)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--fuel-subset", type=int, default=50, help="fuel-optimal solves (slow)")
    ap.add_argument(
        "--controllers",
        nargs="+",
        default=["mpc-fuel-reserve", "mpc-fuel", "mpc-energy", "zemzev"],
        help="registered names, NAME-warmlp, or mpc-fuel-nearest / mpc-energy-nearest",
    )
    ap.add_argument("--lp", action="store_true", help="also compare the LP solver paths")
    ap.add_argument("--banded", action="store_true", help="also time solve_banded vs dptsv")
    ap.add_argument("--demos", type=int, default=0, metavar="N", help="time N demo episodes")
    ap.add_argument("--dispersions", default="standard", help="dispersions of the demo episodes")
    ap.add_argument("--only-demos", action="store_true", help="skip parts 1 and 2")
    ap.add_argument("--only-micro", action="store_true", help="--lp / --banded only")
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
    if not args.only_micro:
        fuel_opt, opt_wall, opt_cpu = fuel_optimal(args.episodes, args.seed, args.fuel_subset)
        print(
            f"{args.episodes} nominal Table 3 episodes (disturbances on, seed {args.seed}); fuel "
            f"ratio over the first {len(fuel_opt)}; cold free-t_f fuel-optimal solve (80 points) "
            f"median {_ms(opt_wall, 50):.1f} ms wall, {_ms(opt_cpu, 50):.1f} ms CPU"
        )
        head = (
            f"{'controller':<22}{'success':>8}{'fuel kg':>9}{'/opt':>7}{'warm ms med/p99':>17}"
            f"{'cpu ms med/p99':>16}{'cold cpu':>9}{'cold/warm':>10}{'fallback%':>10}{'wall s':>8}"
        )
        print(head)
        for name in args.controllers:
            r = fly(name, args.episodes, args.seed, fuel_opt)
            row = f"{name:<22}{100 * r['success']:>7.1f}%{r['fuel']:>9.1f}{r['ratio']:>7.3f}"
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
        t = lp_compare()
        print(
            f"fuel LP of a re-plan (40 points, CPU ms median): scipy linprog {t['scipy']:.3f}, "
            f"highspy + HighsLp {t['highslp']:.3f}, LPSolver {t['cold']:.3f}, LPSolver from "
            f"the last basis {t['warm']:.3f}"
        )
    if args.banded:
        sb, dp = banded_compare()
        print(f"tridiagonal solve (40 x 7, us median): solve_banded {sb:.1f}, dptsv {dp:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
