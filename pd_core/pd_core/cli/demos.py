"""`pd-demos`: build the demonstration memory of a training config as a file, before training.

The flags are `pd-train`'s (a preset plus any field); the memory is what `pd-train` with the same
flags would build before its first update (the open-loop demos file, teacher-flown episodes,
recovery episodes, the first DAgger labels), written with its provenance. Train on it with
`pd-train <the same flags> --demo-memory FILE`: no teacher flies, and a file made for another
config is refused.

Examples:
    pd-demos --preset ocp --seed 1 --out runs/demos/ocp__1.npz
    pd-train --preset ocp --seed 1 --demo-memory runs/demos/ocp__1.npz
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from pd_core.cli.train import join_ray
from pd_core.dqn.config import add_arguments, check_config, from_args


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="pd-demos",
        description=__doc__.split("\n\n")[0] + " Flags as pd-train.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("--out", required=True, type=Path, help="the file to write (.npz)")
    add_arguments(p)
    p.add_argument("--json", action="store_true", help="print the file's provenance as JSON")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        cfg = from_args(args)
        check_config(cfg)
    except (KeyError, ValueError) as exc:
        print(f"pd-demos: {exc}", file=sys.stderr)
        return 2
    if cfg.demo_memory:
        print("pd-demos: --demo-memory reads a memory; pd-demos builds one", file=sys.stderr)
        return 2
    why = join_ray(cfg.address)
    if why is not None:
        print(f"pd-demos: {why}", file=sys.stderr)
        return 2
    # torch and the teachers load only once the flags are known to be good
    from pd_core.dqn.config import training_reward
    from pd_core.dqn.demo_file import read_provenance, write_demo_file
    from pd_core.dqn.demo_memory import build_demo_memory

    t0 = time.perf_counter()
    try:
        memory, info = build_demo_memory(cfg, training_reward(cfg))
    except (FileNotFoundError, ValueError) as exc:
        print(f"pd-demos: {exc}", file=sys.stderr)
        return 2
    if memory is None:
        print(f"pd-demos: {cfg.preset} with these flags has no demonstrations", file=sys.stderr)
        return 2
    path = write_demo_file(args.out, memory, cfg, info)
    record = read_provenance(path)
    if args.json:
        print(json.dumps(record, indent=2, sort_keys=True))
    else:
        print(f"{path}: {len(memory)} transitions in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
