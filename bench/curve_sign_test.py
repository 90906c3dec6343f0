"""Paired sign test of two training runs' selection curves (issue 32): every network, not only
the picks.

    python bench/curve_sign_test.py RUN_A RUN_B

Each run's `evals.csv` holds one greedy evaluation per saved network, all on the same selection
episodes, so networks at the same update count pair up. Prints how many pairs, where A's success
is higher and lower, both means, and the two-sided exact sign test on higher / lower
(`pd_core.experiments.paired`). Where a resumed run logged an update count twice, the later row
(the one the resumed run wrote) counts.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from pd_core.experiments.paired import paired_curves, sign_test
from pd_core.plots import read_csv


def curve(run_dir: Path) -> dict[int, float]:
    """updates -> success rate from RUN_DIR/evals.csv."""
    ev = read_csv(run_dir / "evals.csv")
    return dict(zip(ev["updates"].astype(int).tolist(), ev["success_rate"].tolist(), strict=True))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("run_a", type=Path)
    ap.add_argument("run_b", type=Path)
    a = ap.parse_args(argv)
    cp = paired_curves(curve(a.run_a), curve(a.run_b))
    print(f"A = {a.run_a}, B = {a.run_b}: {cp.networks} networks at equal update counts")
    print(f"mean success  A {100 * cp.mean_a:.2f} %  B {100 * cp.mean_b:.2f} %")
    p = sign_test(cp.a_higher, cp.a_lower)
    print(f"A higher {cp.a_higher}, lower {cp.a_lower}, sign test p = {p:.2g}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
