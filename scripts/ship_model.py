"""Ship a training run's policy under models/: weights, metadata and the per-episode training log.

    scripts/in_env.sh python scripts/ship_model.py runs/<run> models/paper_agent1 \
        [--policy final|best]

Writes models/<name>.pt and .json (the run's metadata plus the run's wall time, env steps and
updates per env step) and models/<name>.episodes.csv (episode, landed, return, k-velocity, fuel,
epsilon: what Fig. 5 of `pd-eval --figures` reads beside the model). The report (.md) is written
by hand from `pd-eval`'s output.
"""

from __future__ import annotations

import argparse
import csv
import json
import shutil
import sys
from pathlib import Path

KEEP = ("episode", "landed", "return", "k_velocity_mps", "fuel_kg", "epsilon")


def ship(run: Path, out: Path, policy: str) -> list[Path]:
    pt, meta_path = run / f"{policy}.pt", run / f"{policy}.json"
    if not pt.is_file() or not meta_path.is_file():
        raise FileNotFoundError(f"{run}: no {policy}.pt/.json (has the run finished?)")
    meta = json.loads(meta_path.read_text())
    rows = list(csv.DictReader((run / "episodes.csv").open()))
    training = meta.setdefault("training", {})
    cfg = training.get("config", {})
    training["shipped_from"] = {
        "policy": policy,
        "episodes_logged": len(rows),
        "successes_logged": sum(int(r["landed"]) for r in rows),
        "updates_per_step": cfg.get("updates_per_step"),
        "target_period_updates": cfg.get("target_period"),
    }
    out.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(pt, out.with_suffix(".pt"))
    out.with_suffix(".json").write_text(json.dumps(meta, indent=2) + "\n")
    log = out.with_suffix(".episodes.csv")
    with log.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(KEEP)
        for r in rows:
            w.writerow([r[k] for k in KEEP])
    return [out.with_suffix(".pt"), out.with_suffix(".json"), log]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("run", type=Path, help="run folder of pd-train")
    ap.add_argument("out", type=Path, help="models/<name> (suffixes are added)")
    ap.add_argument("--policy", choices=("final", "best"), default="final")
    a = ap.parse_args(argv)
    try:
        for p in ship(a.run, a.out, a.policy):
            print(f"wrote {p}")
    except (OSError, ValueError, KeyError) as exc:
        print(f"ship_model: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
