"""`pd-ocp`: solve the OCP of Eq. 4 from the command line, and build the demonstration set.

    pd-ocp solve --position X Y Z --velocity VX VY VZ --mass M [--json]
    pd-ocp demos [--out data/demos_7x7x3.npz] [--extra N --seed S] [--skip-table5] [--json]

Exit codes: 0 success, 1 failed solve, 2 bad arguments.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

import numpy as np
from tqdm import tqdm

from pd_core import discretise as disc
from pd_core import ocp
from pd_core.config import (
    N_ACTIONS_PER_AXIS,
    PAPER_TABLE4,
    PAPER_TABLE5,
    PAPER_TABLE6,
    TABLE3,
    TABLE5_N_IJ,
    TABLE5_N_K,
)
from pd_core.demonstrations import open_loop as demos_mod
from pd_core.ocp.request import MIN_CONTROL_POINTS


def _stats(v: np.ndarray) -> tuple[float, float, float]:
    return float(np.median(v)), float(np.min(v)), float(np.max(v))


def table4(results: list[ocp.OCPResult]) -> dict[str, tuple[float, float, float]]:
    """Our Table 4: final-state, fuel and thrust statistics of the optimal trajectories."""
    fs = np.array([r.states[-1] for r in results])
    thr = np.concatenate([r.step_thrust for r in results])
    return {
        "norm_ij_position_m": _stats(np.linalg.norm(fs[:, 0:2], axis=1)),
        "k_position_m": _stats(fs[:, 2]),
        "norm_ij_velocity_mps": _stats(np.linalg.norm(fs[:, 3:5], axis=1)),
        "k_velocity_mps": _stats(fs[:, 5]),
        "fuel_kg": _stats(np.array([r.fuel for r in results])),
        "T1_n": _stats(thr[:, 0]),
        "T2_n": _stats(thr[:, 1]),
        "T3_n": _stats(thr[:, 2]),
    }


def table6(runs: list[disc.DiscreteRun]) -> dict[str, tuple[float, float, float]]:
    """Our Table 6: final states of the discretised trajectories."""
    fs = np.array([r.final_state for r in runs])
    return {
        "norm_ij_position_m": _stats(np.linalg.norm(fs[:, 0:2], axis=1)),
        "k_position_m": _stats(fs[:, 2]),
        "norm_ij_velocity_mps": _stats(np.linalg.norm(fs[:, 3:5], axis=1)),
        "k_velocity_mps": _stats(fs[:, 5]),
        "fuel_kg": _stats(np.array([r.fuel for r in runs])),
    }


def table5(results: list[ocp.OCPResult]) -> dict[int, list[float]]:
    """Our Table 5: % landed discretised episodes per (n_ij, n_k), all flown as one batch."""
    combos = [(a, a, k) for a in TABLE5_N_IJ for k in TABLE5_N_K]
    n = len(results)
    runs = disc.discretise_batch(results * len(combos), np.repeat(np.array(combos), n, axis=0))
    out: dict[int, list[float]] = {}
    for c, (a, _, _) in enumerate(combos):
        pct = 100.0 * sum(r.landed for r in runs[c * n : (c + 1) * n]) / n
        out.setdefault(a, []).append(round(pct, 1))
    return out


def _print_side_by_side(title: str, ours: dict, paper: dict) -> None:
    print(f"\n{title}\n{'quantity':<22}{'ours median / min / max':>36}   paper median / min / max")
    for k, v in ours.items():
        p = paper.get(k)
        ps = " / ".join(f"{x:.3g}" for x in p) if p else "-"
        print(f"{k:<22}{' / '.join(f'{x:.3g}' for x in v):>36}   {ps}")


def _solver_options(args: argparse.Namespace) -> dict[str, Any]:
    """method (+ options): --paper is SciPy SLSQP with finite-difference gradients (Sec. 3.1)."""
    if args.paper:
        return {"method": "slsqp", "exact_gradients": False}
    return {"method": args.method}


def _solve(args: argparse.Namespace) -> int:
    r = ocp.solve(
        args.position,
        args.velocity,
        args.mass,
        objective=args.objective,
        n_control=args.control_points,
        **_solver_options(args),
    )
    out = {
        "success": r.success,
        "message": r.message,
        "time_of_flight": r.time_of_flight,
        "fuel": r.fuel,
        "cost": r.cost,
        "final_position": r.final_position.tolist(),
        "final_velocity": r.final_velocity.tolist(),
        "solve_time": r.solve_time,
        "method": r.method,
        "objective": r.objective,
        "iterations": r.iterations,
    }
    if args.json:
        print(json.dumps(out, allow_nan=True))
    else:
        for k, v in out.items():
            print(f"{k:>15}: {v}")
    refused = ocp.check_request(
        args.position, args.velocity, args.mass, n_control=args.control_points
    )
    if not r.success and refused is not None:
        return 2
    return 0 if r.success else 1


def _demos(args: argparse.Namespace) -> int:
    states = demos_mod.table1_initial_states()
    quiet = args.json
    results = [
        ocp.solve(s[0:3], s[3:6], s[6], **_solver_options(args))
        for s in tqdm(states, desc="Table 1 OCP solves", disable=quiet)
    ]
    ok = [r for r in results if r.success]
    report: dict[str, Any] = {"n_cases": len(results), "n_converged": len(ok)}
    report["table4"] = table4(ok)
    runs = disc.discretise_batch(ok, N_ACTIONS_PER_AXIS)
    report["table6"] = table6(runs)
    report["landed_7x7x3_pct"] = 100.0 * sum(r.landed for r in runs) / len(runs)
    if not args.skip_table5:
        report["table5"] = table5(ok)
    all_runs = list(runs)
    if args.extra:
        rng = np.random.default_rng(args.seed)
        extra = rng.uniform(TABLE3.lo, TABLE3.hi, size=(args.extra, 7))
        ex = [
            ocp.solve(s[0:3], s[3:6], s[6], **_solver_options(args))
            for s in tqdm(extra, desc="Table 3 extra solves", disable=quiet)
        ]
        all_runs += disc.discretise_batch([r for r in ex if r.success], N_ACTIONS_PER_AXIS)
    demos = demos_mod.runs_to_demos(all_runs)
    meta = {
        "made_by": "pd-ocp demos",
        "method": "slsqp (finite differences, the paper's)" if args.paper else args.method,
        "objective": "energy",
        "initial_states": "Table 1 (33 cases)"
        + (f" + {args.extra} uniform Table 3" if args.extra else ""),
        "seed": args.seed,
        "hindsight": disc.DEFAULT_HINDSIGHT,
        "n_episodes": len(all_runs),
        "n_landed": int(sum(r.landed for r in all_runs)),
    }
    demos_mod.save_demos(args.out, demos, meta)
    report["out"] = str(args.out)
    report["n_transitions"] = int(len(demos.actions))
    if args.json:
        print(json.dumps(report))
        return 0
    _print_side_by_side("Table 4 (optimal trajectories)", report["table4"], PAPER_TABLE4)
    if "table5" in report:
        print("\nTable 5 (% landed), rows n_ij, columns n_k =", list(TABLE5_N_K))
        for a, row in report["table5"].items():
            print(f"{a:>3} ours  " + " ".join(f"{x:5.1f}" for x in row))
            print(f"{'':>3} paper " + " ".join(f"{x:5.1f}" for x in PAPER_TABLE5[a]))
    _print_side_by_side("Table 6 (discretised, 7x7x3)", report["table6"], PAPER_TABLE6)
    print(f"\nlanded (7,7,3): {report['landed_7x7x3_pct']:.1f} % (paper 81.8 %)")
    print(f"wrote {args.out}: {len(all_runs)} episodes, {len(demos.actions)} transitions")
    return 0


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # exit code 2 with usage, as argparse, kept explicit
        self.print_usage(sys.stderr)
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(
        prog="pd-ocp", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    sub = p.add_subparsers(dest="cmd", required=True, parser_class=_Parser)
    s = sub.add_parser("solve", help="solve Eq. 4 from one initial state")
    s.add_argument(
        "--position", type=float, nargs=3, required=True, metavar=("X", "Y", "Z"), help="m"
    )
    s.add_argument(
        "--velocity", type=float, nargs=3, required=True, metavar=("VX", "VY", "VZ"), help="m/s"
    )
    s.add_argument("--mass", type=float, required=True, help="kg")
    s.add_argument(
        "--method",
        choices=ocp.METHODS,
        default=ocp.DEFAULT_METHOD,
        help="qp: fast structured solver (default); slsqp: SciPy SLSQP with exact gradients",
    )
    s.add_argument(
        "--paper",
        action="store_true",
        help="the paper's solver: SciPy SLSQP, finite-difference gradients (about 9 s a case)",
    )
    s.add_argument("--objective", choices=ocp.OBJECTIVES, default="energy")
    s.add_argument(
        "--control-points",
        type=int,
        default=80,
        help=f"per axis, {MIN_CONTROL_POINTS}-{ocp.MAX_CONTROL_POINTS}",
    )
    s.add_argument("--json", action="store_true", help="print one JSON object")
    d = sub.add_parser("demos", help="Tables 4-6 and the demonstration file")
    d.add_argument("--out", default="data/demos_7x7x3.npz")
    d.add_argument("--method", choices=ocp.METHODS, default=ocp.DEFAULT_METHOD)
    d.add_argument(
        "--paper",
        action="store_true",
        help="the paper's solver: SciPy SLSQP, finite-difference gradients (about 9 s a case)",
    )
    d.add_argument("--extra", type=int, default=0, help="add N uniform Table 3 initial states")
    d.add_argument("--seed", type=int, default=0)
    d.add_argument("--skip-table5", action="store_true")
    d.add_argument("--json", action="store_true")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return _solve(args) if args.cmd == "solve" else _demos(args)


if __name__ == "__main__":
    sys.exit(main())
