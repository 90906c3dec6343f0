"""OCP solve time over the Table 1 cases: (a) SLSQP with SciPy finite differences (as the paper),
(b) SLSQP with exact gradients, (c) the fast "qp" method, side by side with costs and ratios;
(d) `qp_fuel`, the fast method on the fuel objective (HiGHS LPs through highspy; its cost is kg).

Run single-threaded BLAS (OPENBLAS_NUM_THREADS=1, set below before numpy loads): on a busy
machine multithreaded BLAS makes tiny products 100x slower.
"""

from __future__ import annotations

import argparse
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from pd_core import ocp  # noqa: E402
from pd_core.demonstrations.open_loop import table1_initial_states  # noqa: E402

VARIANTS = {
    "slsqp_fd": {"method": "slsqp", "exact_gradients": False},
    "slsqp_exact": {"method": "slsqp", "exact_gradients": True},
    "qp": {"method": "qp"},
    "qp_fuel": {"method": "qp", "objective": "fuel"},
}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--cases", type=int, default=33, help="first N of the 33 Table 1 cases")
    ap.add_argument(
        "--fd-cases",
        type=int,
        default=3,
        help="run slsqp_fd (slow: ~1 min a case) on only the first N of those cases",
    )
    ap.add_argument("--variants", nargs="+", choices=list(VARIANTS), default=list(VARIANTS))
    args = ap.parse_args(argv)
    nan = float("nan")
    cases = table1_initial_states()[: args.cases]
    times: dict[str, list[float]] = {v: [] for v in args.variants}
    costs: dict[str, list[float]] = {v: [] for v in args.variants}
    for i, s in enumerate(cases):
        row = [f"case {i:2d}"]
        for v in args.variants:
            if v == "slsqp_fd" and i >= args.fd_cases:
                times[v].append(nan)
                costs[v].append(nan)
                continue
            r = ocp.solve(s[0:3], s[3:6], s[6], **VARIANTS[v])
            times[v].append(r.solve_time)
            costs[v].append(r.cost)  # SLSQP often stops at maxiter a few mm from rest
            row.append(f"{v} {r.solve_time * 1e3:8.1f} ms cost {r.cost:9.2f} ok={int(r.success)}")
        print(" | ".join(row), flush=True)
    print(f"\n{'variant':<12}{'median ms':>10}{'worst ms':>10}{'median cost':>13}")
    for v in args.variants:
        t = np.array(times[v]) * 1e3
        print(f"{v:<12}{np.nanmedian(t):10.1f}{np.nanmax(t):10.1f}{np.nanmedian(costs[v]):13.2f}")
    if "qp" in times:
        for ref in ("slsqp_fd", "slsqp_exact"):
            if ref in times:
                sp = np.nanmedian(np.array(times[ref]) / np.array(times["qp"]))
                rel = (np.array(costs["qp"]) - np.array(costs[ref])) / np.array(costs[ref])
                print(
                    f"qp vs {ref}: median speed-up {sp:.0f}x, cost difference median "
                    f"{np.nanmedian(rel) * 100:+.3f} %, worst {np.nanmax(np.abs(rel)) * 100:.3f} %"
                )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
