"""`pd-eval`: evaluate a trained policy or a reference controller like Table 7 of the paper.

Examples:
    pd-eval models/pd_dqn_best.pt --episodes 1000 --seed 0
    pd-eval --controller zemzev --json
    pd-eval models/pd_dqn_best.pt --compare runs/paper-agent2__1__*/final.pt \\
        --training-log runs/best__1__*/episodes.csv --figures out/figs
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="pd-eval",
        description="Fly N seeded Table 3 episodes with disturbances (greedy actions) and print "
        "Table 7 rows beside the paper's, success and soft-landing rates.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("model", nargs="?", help="policy file (.pt with its .json beside it)")
    p.add_argument("--controller", help="evaluate a reference controller instead (zemzev)")
    p.add_argument("--episodes", type=int, default=1000, help="evaluation episodes")
    p.add_argument("--seed", type=int, default=0, help="episode i uses env seed seed + i")
    p.add_argument("--no-disturbance", action="store_true", help="turn the disturbance force off")
    p.add_argument(
        "--fuel-optimal",
        type=int,
        default=0,
        metavar="N",
        help="compare fuel with pd_core.ocp fuel-optimal solves on the first N episodes",
    )
    p.add_argument("--json", action="store_true", help="print results as JSON")
    p.add_argument("--figures", help="folder to write Figs. 6-8 (and 5 with --training-log)")
    p.add_argument(
        "--compare",
        action="append",
        default=[],
        metavar="NAME=MODEL",
        help="other policies (or controllers as NAME=controller:zemzev) for Fig. 7",
    )
    p.add_argument(
        "--training-log",
        action="append",
        default=[],
        metavar="NAME=EPISODES_CSV",
        help="episodes.csv of training runs for Fig. 5",
    )
    p.add_argument("--name", help="name of the evaluated agent in the report")
    return p


def load_actor(spec: str) -> tuple[Any, str]:
    """A policy file or `controller:<name>`."""
    if spec.startswith("controller:"):
        from pd_core.controllers import make_controller

        name = spec.split(":", 1)[1]
        return make_controller(name), f"controller {name}"
    from pd_core.policy import load_policy

    return load_policy(spec), Path(spec).stem


def _split(spec: str) -> tuple[str, str]:
    if "=" in spec:
        a, b = spec.split("=", 1)
        return a, b
    return Path(spec).stem, spec


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from pd_core.evaluate import (
        format_report,
        fuel_optimal_ratios,
        rollout,
        summarise,
        to_json,
    )
    from pd_core.policy import PolicyLoadError

    if bool(args.model) == bool(args.controller):
        print("pd-eval: give a model file or --controller (not both)", file=sys.stderr)
        return 2
    try:
        actor, name = load_actor(args.model or f"controller:{args.controller}")
    except (PolicyLoadError, ValueError) as exc:
        print(f"pd-eval: {exc}", file=sys.stderr)
        return 2
    name = args.name or name
    ro = rollout(
        actor, args.episodes, args.seed, disturbance=not args.no_disturbance, keep_trajectories=1
    )
    fo = fuel_optimal_ratios(ro, args.fuel_optimal) if args.fuel_optimal > 0 else None
    summary = summarise(ro, fo)
    figures: dict[str, str] = {}
    if args.figures:
        figures = write_figures(args, actor, name, ro)
    if args.json:
        print(to_json(summary, name=name, seed=args.seed, figures=figures))
    else:
        print(format_report(summary, name, args.seed))
        for k, v in figures.items():
            print(f"figure {k}: {v}")
    return 0


def write_figures(args: argparse.Namespace, actor: Any, name: str, ro: Any) -> dict[str, str]:
    from pd_core import plots
    from pd_core.config import DT_S
    from pd_core.evaluate import rollout

    out = Path(args.figures)
    out.mkdir(parents=True, exist_ok=True)
    figs: dict[str, str] = {}
    path, acts = ro.trajectories[0], ro.actions[0]
    thrust = actor.thrust(0) * 0 if len(acts) == 0 else np.array([actor.thrust(a) for a in acts])
    figs["fig6"] = str(
        plots.fig6_trajectory(path, thrust, DT_S, out / "fig6_trajectory.png", f"Fig. 6: {name}")
    )
    finals = {name: ro.final_states}
    for spec in args.compare:
        other_name, other = _split(spec)
        other_actor, _ = load_actor(other)
        finals[other_name] = rollout(other_actor, args.episodes, args.seed).final_states
    figs["fig7"] = str(plots.fig7_final_distributions(finals, out / "fig7_final_states.png"))
    figs["fig8"] = str(
        plots.fig8_initial_j_vs_final_i(
            ro.initial_states, ro.final_states, out / "fig8_j0_vs_final_i.png", name
        )
    )
    if args.training_log:
        logs = dict(_split(s) for s in args.training_log)
        figs["fig5"] = str(plots.fig5_cumulative_successes(logs, out / "fig5_successes.png"))
    (out / "figures.json").write_text(json.dumps(figs, indent=2) + "\n")
    return figs


if __name__ == "__main__":
    sys.exit(main())
