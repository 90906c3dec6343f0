"""`pd-train`: train a DQN lander policy (Sec. 2.3, 3.2) from a preset plus flags.

Examples:
    pd-train --preset paper-agent1 --seed 1
    pd-train --preset paper-agent1 --seed 1 --num-envs 16 --updates-per-step 16  # paper's ratio
    pd-train --preset best --seed 1 --max-minutes 55
    pd-train --resume runs/best__1__20260101-120000 --max-minutes 80
    pd-train --resume runs/best__1__20260101-120000 --device cpu  # a GPU run, on a CPU
    pd-train --preset ocp --address auto  # the teacher's episodes and labels on a Ray cluster
    pd-train --preset paper-agent1 --num-envs 16 --updates-per-step 16 --device cuda \
        --agents paper-agent2:1  # Agents 1 and 2 together in the device loop, one graph a step
"""

from __future__ import annotations

import argparse
import json
import sys

from pd_core.deprecation import show_as_lines
from pd_core.dqn.config import (
    PRESETS,
    TrainConfig,
    add_arguments,
    check_config,
    from_args,
    given_fields,
)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="pd-train",
        description="Train a DQN powered-descent policy. Presets: " + ", ".join(sorted(PRESETS)),
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
        epilog=(
            "The paper's ratio is one gradient update per env transition: with --num-envs N "
            "give --updates-per-step N (the N updates of a step run together after it). "
            "--device auto trains on the GPU when torch sees one (replay memories on the GPU, "
            "the whole update one CUDA graph) and on the CPU otherwise; the run's config.json "
            "and policy metadata record the device used."
        ),
    )
    add_arguments(p)
    p.add_argument("--json", action="store_true", help="print the run summary as JSON")
    p.add_argument("--print-config", action="store_true", help="print the resolved config and exit")
    return p


def join_ray(address: str) -> str | None:
    """Join the Ray cluster the teacher's episodes and labels fly on (`--address`; "": none)
    before any work starts: None, or the one-line reason it cannot."""
    if not address:
        return None
    from pd_core.ray_session import RayUnavailable, connect  # Ray: only if asked

    try:
        connect(address)
    except RayUnavailable as exc:
        return str(exc)
    return None


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    show_as_lines("pd-train")  # an old flag (--shield) is one line on stderr
    # torch loads in seconds: only once the flags are known to be good (`--help` stays instant)
    from pd_core.dqn.demo_file import prepare_demonstrations
    from pd_core.dqn.device_checkpoint import is_loop_checkpoint
    from pd_core.dqn.device_loop import DeviceLoop, uses_device_loop
    from pd_core.dqn.run_log import run_folder
    from pd_core.dqn.train import Trainer

    if args.resume:
        try:
            overrides = given_fields(args, ("preset", "resume"))
            if is_loop_checkpoint(args.resume):
                return report(DeviceLoop.resume(args.resume, overrides).run(), args.json)
            trainer = Trainer.resume(args.resume, overrides)
        except (OSError, ValueError, KeyError, TypeError) as exc:
            print(f"pd-train: cannot resume from {args.resume}: {exc}", file=sys.stderr)
            return 2
        if (reason := join_ray(trainer.cfg.address)) is not None:
            print(f"pd-train: {reason}", file=sys.stderr)
            return 2
    else:
        try:
            cfg = from_args(args)
            check_config(cfg)
        except ValueError as exc:
            print(f"pd-train: {exc}", file=sys.stderr)
            return 2
        if args.print_config:
            print(json.dumps(cfg.to_dict(), indent=2))
            return 0
        if (reason := join_ray(cfg.address)) is not None:
            print(f"pd-train: {reason}", file=sys.stderr)
            return 2
        if uses_device_loop(cfg):
            return run_device_loop(cfg, args)
        try:  # data first: the demonstrations, written into the run folder, then the trainer
            run_dir = run_folder(cfg)
            demos = prepare_demonstrations(cfg, run_dir)
            trainer = Trainer(cfg, run_dir, demos=demos)
        except (FileNotFoundError, ValueError) as exc:
            print(f"pd-train: {exc}", file=sys.stderr)
            return 2
    print(f"pd-train: run folder {trainer.run_dir}", file=sys.stderr)
    summary = trainer.run()
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        for k, v in summary.items():
            print(f"{k}: {v}")
    return 0


def run_device_loop(cfg: TrainConfig, args: argparse.Namespace) -> int:
    """Train `cfg` and its `--agents` together in `pd_core.dqn.device_loop`; print summaries."""
    from pd_core.dqn.device_loop import DeviceLoop, agent_configs

    overrides = given_fields(args, ("preset", "seed", "agents"))
    try:
        cfgs, run_dirs = agent_configs(cfg, overrides)
        loop = DeviceLoop(cfgs, run_dirs)
    except (FileNotFoundError, ValueError) as exc:
        print(f"pd-train: {exc}", file=sys.stderr)
        return 2
    for c, d in zip(cfgs, run_dirs, strict=True):
        print(f"pd-train: device loop, {c.preset} seed {c.seed}: run folder {d}", file=sys.stderr)
    return report(loop.run(), args.json)


def report(summaries: list[dict], as_json: bool) -> int:
    """Print the device loop's run summaries (one per agent); exit status 0."""
    if as_json:
        print(json.dumps(summaries if len(summaries) > 1 else summaries[0], indent=2))
    else:
        for summary in summaries:
            for k, v in summary.items():
                print(f"{k}: {v}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
