"""Write out the runtime config of a format-1 policy file (before the config was pinned).

    python -m pd_core.runtime.migrate models/NAME.json [--network-dtype float32]

A format-1 file named 3-9 of the old shield settings and took the rest, and every constant of
the latency stage, the navigation filter and the fallback, from the code of the day. This writes
the values that code flies today into the file's "runtime" section, explicitly, and sets format
2; a file without shield settings flew the bare network and gets `RuntimeConfig.off()`. The old
"shield" section is kept under "migrated_from" for the record.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path
from typing import Any

from pd_core.runtime.config import LatencyConfig, NavFilterConfig, RulesConfig, RuntimeConfig

# format-1 shield settings that became fields of RulesConfig under the same name
_RULES = (
    "thrust_margin",
    "land_speed_mps",
    "guard_altitude_m",
    "handover_altitude_m",
    "handover_mass_kg",
    "touchdown_speed_mps",
)


def runtime_of_format1(shield: dict[str, Any] | None, network_dtype: str) -> RuntimeConfig:
    """The runtime config a format-1 file with these shield settings (None: none) flies."""
    if not shield:
        return RuntimeConfig.off(network_dtype)
    known = {*_RULES, "measured_thrust", "max_delay_steps", "nav_filter"}
    unknown = set(shield) - known
    if unknown:
        raise ValueError(f"unknown shield setting(s): {', '.join(sorted(unknown))}")
    rules = replace(
        RulesConfig(),
        **{k: float(shield[k]) for k in _RULES if k in shield},
        **(
            {"measured_thrust": bool(shield["measured_thrust"])}
            if "measured_thrust" in shield
            else {}
        ),
    )
    latency = LatencyConfig(
        max_delay_steps=int(shield.get("max_delay_steps", LatencyConfig().max_delay_steps))
    )
    nav = NavFilterConfig(enabled=bool(shield.get("nav_filter", 1.0)))
    return RuntimeConfig(rules=rules, latency=latency, nav_filter=nav, network_dtype=network_dtype)


def migrate_metadata(meta: dict[str, Any], network_dtype: str = "float32") -> dict[str, Any]:
    """Format-2 metadata of format-1 metadata (unchanged if already format 2)."""
    if meta.get("format_version") != 1:
        return meta
    out = {k: v for k, v in meta.items() if k != "shield"}
    out["runtime"] = runtime_of_format1(meta.get("shield"), network_dtype).to_dict()
    out["migrated_from"] = {"format_version": 1, "shield": meta.get("shield")}
    out["format_version"] = 2
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("paths", nargs="+", type=Path, help="policy metadata files (.json)")
    ap.add_argument("--network-dtype", default="float32", choices=("float32", "float64"))
    args = ap.parse_args(argv)
    for p in args.paths:
        js = p.with_suffix(".json")
        meta = json.loads(js.read_text())
        new = migrate_metadata(meta, args.network_dtype)
        if new is meta:
            print(f"{js}: already format {meta.get('format_version')}, unchanged")
            continue
        js.write_text(json.dumps(new, indent=2, sort_keys=True) + "\n")
        print(f"{js}: runtime config written out (format 2)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
