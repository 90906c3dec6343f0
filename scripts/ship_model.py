"""Ship a training run's policy under models/: weights, metadata and the per-episode training log.

    scripts/in_env.sh python scripts/ship_model.py runs/<run> models/paper_agent1 \
        [--policy final|best] [--recipe "COMMAND" --stages RUN1 RUN2 ...]

Writes models/<name>.pt and .json (the run's metadata plus the run's wall time, env steps and
updates per env step) and models/<name>.episodes.csv (episode, landed, return, k-velocity, fuel,
epsilon: what Fig. 5 of `pd-eval --figures` reads beside the model; none for a run that flew no
episode of its own). The report (.md) is written by hand from `pd-eval`'s output.

With --stages (the run folders of a multi-stage recipe, in order, the last one the shipped run),
the JSON also gets `training.lineage`: the recipe command and, per stage, its pd-train command
(preset, seed, a teacher other than the preset's, initial policy), update count and every
demonstration and label source as that stage's <policy>.json records them, so the file says
what taught it without the runs folder.
"""

from __future__ import annotations

import argparse
import csv
import json
import shutil
import sys
from pathlib import Path

from pd_core.dqn.config import PRESETS

KEEP = ("episode", "landed", "return", "k_velocity_mps", "fuel_kg", "epsilon")


def stage_record(number: int, run: Path, policy: str) -> dict:
    """One stage of `training.lineage`: its command, updates and demonstration sources."""
    training = json.loads((run / f"{policy}.json").read_text())["training"]
    cfg = training["config"]
    command = f"pd-train --preset {cfg['preset']} --seed {cfg['seed']}"
    preset_teacher = PRESETS.get(cfg["preset"], {}).get("controller")
    if cfg.get("controller") not in (None, preset_teacher):  # a teacher the preset does not name
        command += f" --controller {cfg['controller']}"
    if cfg.get("init_policy"):
        command += f" --init-policy {cfg['init_policy']}"
    return {
        "stage": number,
        "command": command,
        "policy": f"{run}/{policy}.pt",
        "updates": training["updates"],
        "demos": training["demos"],
    }


def lineage(recipe: str, stages: list[Path], policy: str) -> dict:
    """`training.lineage`: the stages in order; stages before the last ship their best.pt."""
    records = [
        stage_record(i + 1, run, policy if i == len(stages) - 1 else "best")
        for i, run in enumerate(stages)
    ]
    sources = set()
    for record in records:
        demos = record["demos"]
        sources |= {c["name"] for c in demos.get("controller", [])}
        for labels in [demos.get("labels"), *demos.get("dagger_rounds", [])]:
            if labels:
                sources.add(labels["teacher"])
        if "file" in demos:  # open-loop trajectories (--demos)
            sources.add(f"file {demos['file']['path']}")
    return {"recipe": recipe, "sources": sorted(sources), "stages": records}


def ship(
    run: Path, out: Path, policy: str, recipe: str = "", stages: list[Path] | None = None
) -> list[Path]:
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
    if stages:
        if stages[-1].resolve() != run.resolve():
            raise ValueError(f"--stages must end with the shipped run {run}, not {stages[-1]}")
        training["lineage"] = lineage(recipe, stages, policy)
    out.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(pt, out.with_suffix(".pt"))
    out.with_suffix(".json").write_text(json.dumps(meta, indent=2) + "\n")
    log = out.with_suffix(".episodes.csv")
    if not rows:  # a run without interaction (DAgger rounds only) logs no episode
        log.unlink(missing_ok=True)
        return [out.with_suffix(".pt"), out.with_suffix(".json")]
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
    ap.add_argument("--recipe", default="", help="the command that trained it (with --stages)")
    ap.add_argument(
        "--stages", type=Path, nargs="+", help="the recipe's run folders in order, ending with RUN"
    )
    a = ap.parse_args(argv)
    try:
        for p in ship(a.run, a.out, a.policy, a.recipe, a.stages):
            print(f"wrote {p}")
    except (OSError, ValueError, KeyError) as exc:
        print(f"ship_model: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
