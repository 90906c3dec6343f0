"""How fast the teacher labels: DAgger labels and teacher-flown demonstrations per second, on one
worker and on every core, side by side in one run, with the ratios (issue 32).

1. `pd_core.demonstrations.dagger.student_labels`: a student file flies behind its runtime layer
   and the teacher labels, in shadow, every state it decides on.
2. `pd_core.demonstrations.teacher_flown.controller_demonstrations`: the teacher flies behind
   the layer itself (one demonstration per step).

Both under the `standard` dispersions, the same episodes on 1 and on N workers (spawned
processes; each worker's start-up, about 3 s, is counted; episodes go in chunks of 25, so give a
multiple of 25 x workers or the last chunk idles a worker), and with --address as Ray tasks
(`pd-train --address`; local: a local instance, its start counted in the first row).

    python bench/label_speed.py [--policy models/pd_dqn_ocp.pt] [--teacher mpc-fuel-reserve]
                                [--episodes 50] [--workers N] [--address local|auto|host:port]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: one worker = one core
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

from pd_core.demonstrations.dagger import student_labels  # noqa: E402
from pd_core.demonstrations.teacher_flown import controller_demonstrations  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--policy", default=str(ROOT / "models" / "pd_dqn_ocp.pt"))
    ap.add_argument("--teacher", default="mpc-fuel-reserve")
    ap.add_argument("--episodes", type=int, default=50)
    ap.add_argument("--dispersions", default="standard")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--address", default="", help="also on Ray: local, auto or host:port")
    a = ap.parse_args(argv)
    print(f"teacher {a.teacher}, {a.episodes} episodes under {a.dispersions!r}, seed 0")
    print(f"{'what':<28} {'workers':>7} {'labels':>8} {'s':>7} {'labels/s':>9} {'x 1':>5}")
    for what in ("DAgger labels (shadow)", "teacher-flown demos"):
        base = None
        for w in [*sorted({1, a.workers}), *(["ray"] if a.address else [])]:
            where = {"address": a.address} if w == "ray" else {"workers": w}
            t0 = time.perf_counter()
            if what.startswith("DAgger"):
                n = len(
                    student_labels(
                        a.policy, a.teacher, a.episodes, 0, a.dispersions, **where
                    )["labels"]
                )  # fmt: skip
            else:
                d = controller_demonstrations(
                    a.teacher, a.episodes, 0, dispersions=a.dispersions, behind_layer=True,
                    **where,
                )  # fmt: skip
                n = len(d["actions"])
            dt = time.perf_counter() - t0
            rate = n / dt
            base = base or rate
            print(f"{what:<28} {w:>7} {n:>8} {dt:>7.1f} {rate:>9.0f} {rate / base:>5.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
