"""Evaluation reports over the episode runner (`pd_core.episodes`): fuel against the optimum,
Table 7 beside the paper (Sec. 3.2, 4.4), JSON.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from typing import Any

import numpy as np

from pd_core.config import PAPER_TABLE7
from pd_core.episodes import Rollouts
from pd_core.runtime.decision import describe_counts

QUANTITIES = ("norm_ij_position_m", "norm_ij_velocity_mps", "k_velocity_mps", "fuel_kg")
LABELS = {
    "norm_ij_position_m": "Norm ij-position (m)",
    "norm_ij_velocity_mps": "Norm ij-velocity (m/s)",
    "k_velocity_mps": "k-velocity (m/s)",
    "fuel_kg": "Fuel (kg)",
}


def fuel_optimal_ratios(ro: Rollouts, subset: int) -> dict[str, Any]:
    """Fuel of the first `subset` episodes relative to the fuel-optimal landing (pd_core.ocp).

    The solves use the RL thrust limits (Sec. 4.1) and no disturbance (the nominal problem).
    Solves that end with `success` False but a finite fuel (typically "converged; final state
    misses rest at the pad" by centimetres) are kept and counted in `inexact_solves`; solves
    without a fuel figure are skipped and counted in `failed_solves`.
    """
    try:  # the OCP (scipy) is only needed for this comparison
        from pd_core import ocp
        from pd_core.config import RL_THRUST
    except ImportError as exc:
        return {"available": False, "message": f"pd_core.ocp not available: {exc}"}
    ratios, failures, inexact = [], 0, 0
    n = int(min(subset, len(ro.landed)))
    for s, fuel in zip(ro.initial_states[:n], ro.fuel_kg[:n], strict=True):
        try:
            res = ocp.solve(s[0:3], s[3:6], s[6], objective="fuel", limits=RL_THRUST)
        except Exception as exc:  # noqa: BLE001 - any solver problem is reported, not raised
            return {"available": False, "message": f"ocp.solve failed: {exc}"}
        f_opt = float(getattr(res, "fuel", float("nan")))
        if not np.isfinite(f_opt) or f_opt <= 0:
            failures += 1
            continue
        inexact += not res.success
        ratios.append(fuel / f_opt)
    r = np.array(ratios)
    return {
        "available": True,
        "subset": n,
        "failed_solves": failures,
        "inexact_solves": inexact,
        "median_ratio": float(np.median(r)) if r.size else None,
        "min_ratio": float(np.min(r)) if r.size else None,
        "max_ratio": float(np.max(r)) if r.size else None,
    }


def format_report(summary: dict[str, Any], name: str, seed: int) -> str:
    """Text table: our rows beside the paper's Table 7 (Agent 1 and Agent 2)."""
    lines = [
        f"pd-eval: {name}, {summary['episodes']} episodes, Table 3 initial states, "
        f"disturbances on, seed {seed}",
        "",
        f"{'Quantity':<24}{'median':>10}{'min':>10}{'max':>10}   "
        f"{'paper A1 (median/min/max)':>28}   {'paper A2 (median/min/max)':>28}",
    ]
    for k in QUANTITIES:
        row = summary["table7"][k]
        a1 = PAPER_TABLE7["agent1"][k]
        a2 = PAPER_TABLE7["agent2"][k]
        lines.append(
            f"{LABELS[k]:<24}{row['median']:>10.4g}{row['min']:>10.4g}{row['max']:>10.4g}   "
            f"{_triple(a1):>28}   {_triple(a2):>28}"
        )
    lines += [
        "",
        f"success rate (z < 0.01 m, |x| < 5 m, |v| < 2 m/s): {100 * summary['success_rate']:.1f} %",
        f"soft-landing rate (k-velocity > -2 m/s):           "
        f"{100 * summary['soft_landing_rate']:.1f} %",
        f"out of time:                                       "
        f"{100 * summary['out_of_time_rate']:.1f} %",
        f"mean return (training reward):                     {summary['mean_return']:.2f}",
    ]
    if "layer_steps" in summary:
        lines.append(f"runtime layer: {describe_layer(summary)}")
    fo = summary.get("fuel_optimal")
    if fo:
        if fo.get("available"):
            lines.append(
                f"fuel / fuel-optimal (first {fo['subset']} episodes; {fo['failed_solves']} "
                f"failed, {fo['inexact_solves']} inexact solves): median "
                f"{fo['median_ratio']:.3f}, min {fo['min_ratio']:.3f}, max {fo['max_ratio']:.3f}"
            )
        else:
            lines.append(f"fuel-optimal comparison unavailable: {fo['message']}")
    return "\n".join(lines)


def describe_layer(summary: dict[str, Any]) -> str:
    """What the runtime layer changed in a `summarise` of an agent flown behind one."""
    return f"{describe_counts(summary['layer_steps'])}, {100 * summary['layer_changed_rate']:.1f} %"


def _triple(t: tuple[float, float, float]) -> str:
    return f"{t[0]:.3g} / {t[1]:.3g} / {t[2]:.3g}"


def to_json(summary: dict[str, Any], **extra: Any) -> str:
    return json.dumps({**summary, **extra}, indent=2, sort_keys=True, default=_json_default)


def _json_default(o: Any) -> Any:
    if isinstance(o, np.generic):
        return o.item()
    if hasattr(o, "__dataclass_fields__"):
        return asdict(o)
    return str(o)


__all__ = [
    "LABELS",
    "QUANTITIES",
    "describe_layer",
    "format_report",
    "fuel_optimal_ratios",
    "to_json",
]
