"""Training sweeps on Ray Tune: (presets x pd-train flag values) x seeds, one trial each.

A sweep lives in one folder:

    <sweep>/sweep.json     the trials (configuration, preset, overrides, seed, run folder)
    <sweep>/runs/<config>__seed<s>/   each trial's usual pd-train run folder (evals.csv, ...)
    <sweep>/tune/          Ray Tune's experiment state (what `Tuner.restore` resumes)
    <sweep>/summary.json, <sweep>/success_vs_wall.png

Each trial trains with `pd_core.dqn.train.Trainer` and reports every periodic evaluation to Tune
as it happens. A trial that restarts (worker lost, sweep resumed) continues from its run
folder's checkpoint.pt, so no finished training is redone; the summary is read from the run
folders, so it is the same however often the sweep was interrupted.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import math
import re
import sys
from dataclasses import fields
from pathlib import Path
from typing import Any

import numpy as np
import ray  # optional heavy dependency: imported only by the Ray code paths
from ray import tune

from pd_core import plots
from pd_core.dqn.checkpoint import CHECKPOINT
from pd_core.dqn.config import TrainConfig, current_names, preset
from pd_core.dqn.demo_file import prepare_demonstrations
from pd_core.dqn.train import Trainer

SPEC = "sweep.json"
SUCCESS_TARGET = 0.99


def parse_value(field: str, text: str) -> Any:
    """A pd-train flag value of TrainConfig field `field` from text (ValueError if unknown)."""
    types = {f.name: str(f.type) for f in fields(TrainConfig)}
    if field not in types:
        raise ValueError(f"unknown pd-train field {field!r}; see pd-train --help")
    kind = types[field]
    if kind in ("bool", "<class 'bool'>"):
        return text.lower() in ("1", "true", "yes", "on")
    if field == "hidden":
        return tuple(int(x) for x in re.split(r"[,x ]+", text.strip("()[] ")) if x)
    return {"int": int, "float": float}.get(kind, str)(text)


def parse_assignments(items: list[str], many: bool) -> dict[str, Any]:
    """FIELD=VALUE (many: FIELD=V1,V2,... ; `hidden` lists use 'x': 300x200x300) pairs; an old
    field name (shield) is its new one (`current_names`: it warns)."""
    texts: dict[str, str] = {}
    for item in items:
        if "=" not in item:
            raise ValueError(f"expected FIELD=VALUE, got {item!r}")
        k, v = item.split("=", 1)
        texts[k.strip().replace("-", "_")] = v
    return {
        k: [parse_value(k, x) for x in v.split(",")] if many else parse_value(k, v)
        for k, v in current_names(texts).items()
    }


def slug(preset_name: str, overrides: dict[str, Any]) -> str:
    parts = [preset_name] + [f"{k}={_fmt(v)}" for k, v in sorted(overrides.items())]
    return ",".join(parts)


def _fmt(v: Any) -> str:
    return "x".join(map(str, v)) if isinstance(v, (tuple, list)) else str(v)


def plan_trials(
    sweep_dir: Path,
    presets: list[str],
    grid: dict[str, list[Any]],
    fixed: dict[str, Any],
    seeds: list[int],
) -> list[dict[str, Any]]:
    """One trial per (preset, grid point, seed); checks every config builds."""
    keys = sorted(grid)
    trials = []
    for p in presets:
        for values in itertools.product(*(grid[k] for k in keys)):
            point = dict(zip(keys, values, strict=True))
            name = slug(p, point)
            for s in seeds:
                overrides = {**fixed, **point}
                preset(p, seed=s, **overrides)  # ValueError now rather than in a trial
                run = sweep_dir / "runs" / f"{re.sub(r'[^A-Za-z0-9_.=,-]', '_', name)}__seed{s}"
                trials.append(
                    {
                        "config": name,
                        "preset": p,
                        "overrides": {k: _jsonable(v) for k, v in overrides.items()},
                        "seed": s,
                        "run_dir": str(run.resolve()),
                    }
                )
    return trials


def _jsonable(v: Any) -> Any:
    return list(v) if isinstance(v, tuple) else v


def run_trial(config: dict[str, Any]) -> None:
    """The Tune trainable: train one trial into its run folder, reporting every evaluation."""
    t = config["trial"]
    run_dir = Path(t["run_dir"])
    overrides = dict(t["overrides"])
    if "hidden" in overrides:
        overrides["hidden"] = tuple(overrides["hidden"])
    report = tune.report
    if (run_dir / CHECKPOINT).is_file():
        trainer = Trainer.resume(run_dir, {"progress": False}, on_eval=report)
        trainer.quiet = True
    else:
        for stale in run_dir.glob("*.csv"):  # logs of an attempt that died before checkpointing
            stale.unlink()
        cfg = preset(t["preset"], seed=t["seed"], run_dir=str(run_dir), progress=False, **overrides)
        demos = prepare_demonstrations(cfg, run_dir)  # data first
        trainer = Trainer(cfg, run_dir=run_dir, quiet=True, on_eval=report, demos=demos)
    trainer.run()


def run_sweep(
    sweep_dir: Path,
    trials: list[dict[str, Any]] | None = None,
    asha: bool = False,
    concurrent: int | None = None,
    max_failures: int = 2,
) -> dict[str, Any]:
    """Run (or, when `trials` is None, resume) the sweep in `sweep_dir` on the connected Ray
    session; returns the summary (also written to summary.json and success_vs_wall.png)."""
    sweep_dir = sweep_dir.resolve()
    spec_path = sweep_dir / SPEC
    if trials is None:
        spec = json.loads(spec_path.read_text())
    else:
        sweep_dir.mkdir(parents=True, exist_ok=True)
        spec = {"trials": trials, "asha": asha}
        spec_path.write_text(json.dumps(spec, indent=2) + "\n")
    tune_dir = sweep_dir / "tune"
    trainable = tune.with_resources(run_trial, {"cpu": 1})
    if trials is None and tune.Tuner.can_restore(str(tune_dir)):
        tuner = tune.Tuner.restore(
            str(tune_dir), trainable, resume_unfinished=True, restart_errored=True
        )
    else:
        tuner = _new_tuner(sweep_dir, spec, trainable, concurrent, max_failures)
    with contextlib.redirect_stdout(sys.stderr):  # Tune's status tables: stdout stays for results
        grid = tuner.fit()
    summary = summarise_sweep(sweep_dir)
    summary["unfinished_trials"] = len(spec["trials"]) - grid.num_terminated
    return summary


def _new_tuner(
    sweep_dir: Path, spec: dict[str, Any], trainable: Any, concurrent: int | None, failures: int
) -> Any:
    scheduler = None
    if spec["asha"]:
        from ray.tune.schedulers import ASHAScheduler  # only with --asha

        scheduler = ASHAScheduler(time_attr="wall_s", max_t=10**9, grace_period=120.0)
    cpus = max(1, int(ray.cluster_resources().get("CPU", 1)))
    return tune.Tuner(
        trainable,
        param_space={"trial": tune.grid_search(spec["trials"])},
        tune_config=tune.TuneConfig(
            metric="success_rate",
            mode="max",
            scheduler=scheduler,
            max_concurrent_trials=concurrent or cpus,
            trial_dirname_creator=lambda tr: Path(tr.config["trial"]["run_dir"]).name,
        ),
        run_config=tune.RunConfig(
            name="tune",
            storage_path=str(sweep_dir),
            verbose=0,
            failure_config=tune.FailureConfig(max_failures=failures),
        ),
    )


# --- summary --------------------------------------------------------------------------------


def trial_result(run_dir: Path) -> dict[str, Any]:
    """Last evaluation's success and fuel, minutes to the first success >= 99 %, and the curve."""
    path = run_dir / "evals.csv"
    ev = plots.read_csv(path) if path.is_file() else {}
    if not ev or not len(ev.get("wall_s", [])):
        return {"success": None, "fuel_kg": None, "minutes_to_99": None, "curve": ([], [])}
    ev = {k: v[_surviving_rows(ev["wall_s"])] for k, v in ev.items()}
    hit = np.flatnonzero(ev["success_rate"] >= SUCCESS_TARGET)
    return {
        "success": float(ev["success_rate"][-1]),
        "fuel_kg": float(ev["fuel_median"][-1]),
        "minutes_to_99": float(ev["wall_s"][hit[0]] / 60.0) if hit.size else None,
        "curve": ((ev["wall_s"] / 60.0).tolist(), ev["success_rate"].tolist()),
    }


def _surviving_rows(wall_s: np.ndarray) -> np.ndarray:
    """Indices of the rows a resumed run did not supersede: a run resumed from a checkpoint
    logs again from the checkpoint's time, so a row is kept only if every later row is later."""
    later_min = np.minimum.accumulate(wall_s[::-1])[::-1]
    keep = np.append(wall_s[:-1] < later_min[1:], True)
    return np.flatnonzero(keep)


def _stats(values: list[float | None]) -> dict[str, Any]:
    v = [x for x in values if x is not None and math.isfinite(x)]
    return {
        "mean": float(np.mean(v)) if v else None,
        "std": float(np.std(v, ddof=1)) if len(v) > 1 else (0.0 if v else None),
        "min": float(np.min(v)) if v else None,
        "max": float(np.max(v)) if v else None,
        "per_seed": values,
    }


def summarise_sweep(sweep_dir: Path) -> dict[str, Any]:
    """Per configuration: mean, spread and per-seed success, fuel and minutes to 99 %."""
    spec = json.loads((sweep_dir / SPEC).read_text())
    by_config: dict[str, list[dict[str, Any]]] = {}
    for t in spec["trials"]:
        by_config.setdefault(t["config"], []).append(t)
    configs, curves = {}, {}
    for name, trials in by_config.items():
        res = [trial_result(Path(t["run_dir"])) for t in trials]
        configs[name] = {
            "seeds": [t["seed"] for t in trials],
            "run_dirs": [t["run_dir"] for t in trials],
            "success": _stats([r["success"] for r in res]),
            "fuel_kg": _stats([r["fuel_kg"] for r in res]),
            "minutes_to_99": _stats([r["minutes_to_99"] for r in res]),
            "reached_99": sum(r["minutes_to_99"] is not None for r in res),
        }
        curves[name] = [(np.array(r["curve"][0]), np.array(r["curve"][1])) for r in res]
    png = plots.sweep_success_bands(curves, sweep_dir / "success_vs_wall.png")
    summary = {"sweep_dir": str(sweep_dir), "configs": configs, "png": str(png)}
    (sweep_dir / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary


def format_summary(summary: dict[str, Any]) -> str:
    def ms(s: dict[str, Any], scale: float = 1.0, fmt: str = ".1f") -> str:
        if s["mean"] is None:
            return "-"
        return f"{s['mean'] * scale:{fmt}} +- {s['std'] * scale:{fmt}}"

    def seeds(s: dict[str, Any], scale: float = 1.0, fmt: str = ".1f") -> str:
        return " ".join("-" if v is None else f"{v * scale:{fmt}}" for v in s["per_seed"])

    lines = [f"pd-sweep: {summary['sweep_dir']}", ""]
    for name, c in summary["configs"].items():
        n = len(c["seeds"])
        lines += [
            f"{name}  (seeds {' '.join(map(str, c['seeds']))})",
            f"  success %        {ms(c['success'], 100):>16}   per seed: "
            f"{seeds(c['success'], 100)}",
            f"  fuel kg          {ms(c['fuel_kg']):>16}   per seed: {seeds(c['fuel_kg'])}",
            f"  min to >= 99 %   {ms(c['minutes_to_99'], 1, '.2f'):>16}   per seed: "
            f"{seeds(c['minutes_to_99'], 1, '.2f')}   ({c['reached_99']}/{n} reached)",
        ]
    lines += ["", f"success against wall time: {summary['png']}"]
    return "\n".join(lines)
