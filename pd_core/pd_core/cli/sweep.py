"""`pd-sweep`: a grid of pd-train presets and flags x seeds as Ray Tune trials.

Examples:
    pd-sweep --preset best --seeds 1 2 --max-minutes 2
    pd-sweep --preset best --grid lr=1e-3,3e-4 --grid n_step=1,3 --seeds 1 2 3 --max-minutes 30
    pd-sweep --preset paper-agent2 --preset best --seeds 1 2 --set eval_every_s=60 --json
    pd-sweep --resume runs/sweep-20260101-120000          # after an interruption
    pd-sweep ... --address auto                           # on a running cluster (ray start)
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from pd_core.deprecation import show_as_lines
from pd_core.dqn.config import PRESETS


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="pd-sweep",
        description="Train every (preset, grid point) for every seed as Ray Tune trials, each "
        "into its own pd-train run folder, and summarise per configuration: mean, spread and "
        "per-seed success, fuel and minutes to the first evaluation >= 99 %.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument(
        "--preset",
        action="append",
        choices=sorted(PRESETS),
        help="preset(s) to sweep (repeatable; default: best)",
    )
    p.add_argument("--seeds", type=int, nargs="+", default=[1], help="seeds of every config")
    p.add_argument(
        "--grid",
        action="append",
        default=[],
        metavar="FIELD=V1,V2",
        help="pd-train field and its values to sweep (repeatable: the grid is their product)",
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        help="pd-train field fixed for every trial (repeatable)",
    )
    p.add_argument("--max-minutes", type=float, help="training budget of every trial (minutes)")
    p.add_argument("--dir", help="sweep folder (default runs/sweep-<time>)")
    p.add_argument("--resume", metavar="SWEEP_DIR", help="resume an interrupted sweep")
    p.add_argument("--asha", action="store_true", help="stop weak trials early (ASHA; off)")
    p.add_argument("--concurrent", type=int, help="trials at once (default: the cluster's CPUs)")
    p.add_argument(
        "--address", help="Ray cluster to join: auto or ray://host:port (default: local Ray)"
    )
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    show_as_lines("pd-sweep")  # an old field name (shield=) is one line on stderr
    from pd_core.experiments import sweep  # imports Ray and torch: only when a sweep really runs
    from pd_core.ray_session import RayUnavailable, connect

    try:
        trials = None
        if args.resume:
            sweep_dir = Path(args.resume)
            if not (sweep_dir / sweep.SPEC).is_file():
                raise ValueError(f"{sweep_dir} holds no {sweep.SPEC}: not a pd-sweep folder")
        else:
            sweep_dir = Path(args.dir or f"runs/sweep-{time.strftime('%Y%m%d-%H%M%S')}")
            fixed = sweep.parse_assignments(args.set, many=False)
            if args.max_minutes is not None:
                fixed["max_minutes"] = args.max_minutes
            grid = sweep.parse_assignments(args.grid, many=True)
            trials = sweep.plan_trials(sweep_dir, args.preset or ["best"], grid, fixed, args.seeds)
        connect(args.address)
    except (ValueError, RayUnavailable) as exc:
        print(f"pd-sweep: {exc}", file=sys.stderr)
        return 2
    n = len(trials) if trials is not None else "the remaining"
    print(f"pd-sweep: {n} trials in {sweep_dir.resolve()}", file=sys.stderr)
    summary = sweep.run_sweep(sweep_dir, trials, asha=args.asha, concurrent=args.concurrent)
    print(json.dumps(summary, indent=2) if args.json else sweep.format_summary(summary))
    if summary["unfinished_trials"]:
        print(
            f"pd-sweep: {summary['unfinished_trials']} trial(s) unfinished (interrupted or "
            f"failed); continue with: pd-sweep --resume {sweep_dir}",
            file=sys.stderr,
        )
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
