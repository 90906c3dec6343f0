"""The student's figures over seeds, one row per arm, mean ± sd (issue 32: the three seeds and the
demonstrator ablation): nominal success, median fuel over the fuel-optimal landing, median miss,
the share of actions the runtime layer changed, and the `standard` campaign mean and its lowest
scenario. Every file flies behind its own runtime layer, on the same episodes.

    python bench/student_table.py ocp=runs/ocp__1/stage2/best.pt,runs/ocp__2/stage2/best.pt \\
        zemzev-vernier=runs/ablation_zemzev-vernier__1/stage2/best.pt \\
        [--episodes 10000] [--fuel-optimal 20] [--campaign standard] [--campaign-episodes 2000]
        [--seed 0] [--json OUT.json]

Nominal: episodes seed .. seed + episodes - 1 (`pd-eval FILE --episodes N --seed S
--fuel-optimal 20` gives the same numbers for one file); the campaign as `pd-eval FILE
--dispersions standard --episodes E --seed S`. sd is the sample standard deviation over the
arm's files (none for one file).
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from typing import Any

import numpy as np

from pd_core.dispersions import load_scenarios
from pd_core.episodes import layer_changed_rate, rollout
from pd_core.experiments.campaign import run_campaign
from pd_core.experiments.evaluate import fuel_optimal_ratios
from pd_core.runtime.build import build

COLUMNS = (
    ("nominal_success_pct", "nominal %", "{:.2f}"),
    ("fuel_ratio", "fuel / opt", "{:.3f}"),
    ("miss_p50_m", "miss p50 m", "{:.2f}"),
    ("layer_changed_pct", "layer %", "{:.1f}"),
    ("bare_nominal_pct", "bare nominal %", "{:.1f}"),
    ("campaign_mean_pct", "campaign %", "{:.2f}"),
    ("campaign_min_pct", "lowest %", "{:.2f}"),
)


def measure(path: str, a: argparse.Namespace) -> dict[str, Any]:
    """The figures of one policy file."""
    actor = build(path).actor
    ro = rollout(actor, a.episodes, a.seed)
    fo = fuel_optimal_ratios(ro, a.fuel_optimal) if a.fuel_optimal > 0 else {}
    bare = rollout(build(f"bare:{path}").actor, a.episodes, a.seed)
    flown = run_campaign({"s": path}, load_scenarios(a.campaign), a.campaign_episodes, a.seed)
    per = {scen: float(np.mean(cells["s"].landed)) * 100 for scen, cells in flown.items()}
    low = min(per, key=per.__getitem__)
    return {
        "file": path,
        "nominal_success_pct": float(np.mean(ro.landed)) * 100,
        "nominal_landed": int(np.sum(ro.landed)),
        "fuel_ratio": fo.get("median_ratio"),
        "miss_p50_m": float(np.median(np.linalg.norm(ro.final_states[:, 0:2], axis=1))),
        "layer_changed_pct": 100.0 * (layer_changed_rate(ro) or 0.0),
        "bare_nominal_pct": float(np.mean(bare.landed)) * 100,
        "campaign_mean_pct": float(np.mean(list(per.values()))),
        "campaign_min_pct": per[low],
        "campaign_lowest": low,
        "campaign": per,
    }


def mean_sd(values: list[float | None], fmt: str) -> str:
    v = [x for x in values if x is not None]
    if not v:
        return "-"
    if len(v) == 1:
        return fmt.format(v[0])
    return f"{fmt.format(statistics.mean(v))} ± {fmt.format(statistics.stdev(v))}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("arms", nargs="+", metavar="ARM=FILE[,FILE...]")
    ap.add_argument("--episodes", type=int, default=10_000, help="nominal episodes")
    ap.add_argument("--fuel-optimal", type=int, default=20, help="fuel-optimal solves (first N)")
    ap.add_argument("--campaign", default="standard")
    ap.add_argument("--campaign-episodes", type=int, default=2000, help="per scenario")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", help="write every file's figures here")
    a = ap.parse_args(argv)
    arms: dict[str, list[dict[str, Any]]] = {}
    for spec in a.arms:
        name, _, files = spec.partition("=")
        if not files:
            ap.error(f"expected ARM=FILE[,FILE...], got {spec!r}")
        arms[name] = []
        for path in files.split(","):
            t0 = time.perf_counter()
            m = measure(path, a)
            arms[name].append(m)
            print(
                f"{name:<16} {path}: nominal {m['nominal_landed']}/{a.episodes}, "
                f"fuel {mean_sd([m['fuel_ratio']], '{:.3f}')}x, "
                f"layer {m['layer_changed_pct']:.1f} %, "
                f"{a.campaign} {m['campaign_mean_pct']:.2f} % (lowest {m['campaign_lowest']} "
                f"{m['campaign_min_pct']:.2f}) [{time.perf_counter() - t0:.0f} s]",
                flush=True,
            )
    print(
        f"\nnominal {a.episodes} episodes and {a.campaign} {a.campaign_episodes} per scenario, "
        f"seed {a.seed}; fuel: median of the first {a.fuel_optimal}; mean ± sd over files"
    )
    print("| arm | files | " + " | ".join(c[1] for c in COLUMNS) + " |")
    print("| --- | --- | " + " | ".join("---" for _ in COLUMNS) + " |")
    for name, rows in arms.items():
        cells = [mean_sd([r[k] for r in rows], fmt) for k, _h, fmt in COLUMNS]
        print(f"| {name} | {len(rows)} | " + " | ".join(cells) + " |")
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"args": vars(a), "arms": arms}, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
