"""Paired sign test of two training runs' selection curves (issue 32): every network, not only
the picks.

    python bench/curve_sign_test.py RUN_A RUN_B [--from-updates N]

Each run's `evals.csv` holds one greedy evaluation per saved network, all on the same selection
episodes, so networks at the same update count pair up. Prints how many pairs, where A's success
is higher and lower, both means, and the two-sided exact sign test on higher / lower
(`pd_core.experiments.paired`).
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

from pd_core.experiments.paired import paired_curves, sign_test


def curve(run_dir: Path, from_updates: int) -> dict[int, float]:
    """updates -> success rate from RUN_DIR/evals.csv, from `from_updates` on."""
    with open(run_dir / "evals.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    out = {int(r["updates"]): float(r["success_rate"]) for r in rows}
    return {u: s for u, s in out.items() if u >= from_updates}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("run_a", type=Path)
    ap.add_argument("run_b", type=Path)
    ap.add_argument("--from-updates", type=int, default=0, help="ignore earlier networks")
    a = ap.parse_args(argv)
    cp = paired_curves(curve(a.run_a, a.from_updates), curve(a.run_b, a.from_updates))
    print(f"A = {a.run_a}, B = {a.run_b}: {cp.networks} networks at equal update counts")
    print(f"mean success  A {100 * cp.mean_a:.2f} %  B {100 * cp.mean_b:.2f} %")
    p = sign_test(cp.a_higher, cp.a_lower)
    print(f"A higher {cp.a_higher}, lower {cp.a_lower}, sign test p = {p:.2g}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
