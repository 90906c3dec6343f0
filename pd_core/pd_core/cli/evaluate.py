"""`pd-eval`: evaluate a trained policy or a reference controller like Table 7 of the paper,
or run a dispersion campaign (every scenario for every agent), here or sharded over Ray.

Examples:
    pd-eval models/pd_dqn_best.pt --episodes 1000 --seed 0
    pd-eval --controller zemzev --json
    pd-eval models/pd_dqn_best.pt --compare runs/paper-agent2__1__*/final.pt \\
        --training-log runs/best__1__*/episodes.csv --figures out/figs
    pd-eval models/pd_dqn_best.pt --dispersions standard --compare zemzev=controller:zemzev
    pd-eval --controller zemzev --dispersions mass,all --reachability
    pd-eval models/pd_dqn_best.pt --episodes 100000 --ray [--shards 8] [--address auto]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from pd_core import plots
from pd_core.config import DT_S
from pd_core.deprecation import show_as_lines
from pd_core.dispersions import NOMINAL, Dispersions, load_scenarios
from pd_core.episodes import Rollouts, rollout, summarise
from pd_core.experiments.campaign import format_table, reachability, run_campaign, table, write_json
from pd_core.experiments.evaluate import describe_layer, format_report, fuel_optimal_ratios, to_json
from pd_core.experiments.table7 import table7_blocks
from pd_core.runtime.build import build
from pd_core.runtime.policy_file import PolicyLoadError
from pd_core.teachers.registry import CONTROLLERS


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="pd-eval",
        description="Fly N seeded Table 3 episodes with disturbances (greedy actions) and print "
        "Table 7 rows beside the paper's, success and soft-landing rates.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("model", nargs="?", help="policy file (.pt with its .json beside it)")
    p.add_argument(
        "--controller",
        help=f"evaluate a reference controller instead ({', '.join(CONTROLLERS)})",
    )
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
        help="other policies (or controllers as NAME=controller:zemzev) flown on the same "
        "episodes: Table 7 blocks side by side, Figs. 5 and 7. A file flies as its metadata "
        "says (runtime layer or not); bare:FILE flies the network alone, layer:FILE behind "
        "the default runtime layer, layer:controller:NAME the controller behind it (shield: is "
        "the deprecated old name of layer:); "
        "set:K=V,K=V:SPEC flies SPEC with those runtime-layer settings changed (e.g. "
        "set:nav_filter=0,touchdown_speed_mps=0:FILE)",
    )
    p.add_argument(
        "--training-log",
        action="append",
        default=[],
        metavar="NAME=EPISODES_CSV",
        help="episodes.csv of training runs for Fig. 5 (a model's <stem>.episodes.csv beside it "
        "is used without this flag)",
    )
    p.add_argument("--name", help="name of the evaluated agent in the report")
    g = p.add_argument_group("dispersion campaigns and Ray")
    g.add_argument(
        "--dispersions",
        metavar="NAME|FILE.yaml",
        help="run a campaign: every scenario (a name of pd_core.dispersions.SCENARIOS, a comma "
        "list, the campaign 'standard' (the ten judged scenarios) or 'broad' (those and harsher "
        "ones), or a YAML file) for every agent (the model and each --compare); prints one "
        "table and writes campaign.json and campaign.png to --out",
    )
    g.add_argument("--out", help="folder for campaign.json/.png (default out/campaign-<time>)")
    g.add_argument(
        "--reachability",
        action="store_true",
        help="judge every episode some agent failed with pd_core.experiments.reachability (OCP "
        "plans and a full-thrust braking bound, 0.1-2 s each): the table adds the episodes out "
        "of reach per scenario and each agent's success %% over the reachable ones",
    )
    g.add_argument(
        "--ray", action="store_true", help="fly the episodes as Ray tasks (same numbers)"
    )
    g.add_argument("--shards", type=int, help="Ray shards per scenario and agent (default: auto)")
    g.add_argument(
        "--address",
        help="Ray cluster to join: auto or ray://host:port (default: a local Ray instance)",
    )
    g.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


def _split(spec: str) -> tuple[str, str]:
    if "=" in spec:
        a, b = spec.split("=", 1)
        return a, b
    return Path(spec).stem, spec


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    show_as_lines("pd-eval")  # an old spec prefix (shield:) is one line on stderr
    if bool(args.model) == bool(args.controller):
        print("pd-eval: give a model file or --controller (not both)", file=sys.stderr)
        return 2
    if args.episodes < 1 or args.fuel_optimal < 0 or (args.shards is not None and args.shards < 1):
        print("pd-eval: --episodes and --shards must be >= 1, --fuel-optimal >= 0", file=sys.stderr)
        return 2
    if args.reachability and not args.dispersions:
        print("pd-eval: --reachability judges a campaign: give --dispersions", file=sys.stderr)
        return 2
    spec = args.model or f"controller:{args.controller}"
    try:
        built = build(spec)
        actor, name = built.actor, built.label
        if args.dispersions:
            return campaign_main(args, spec, args.name or name)
        ro = _rollouts(args, spec, actor)
        others = _compared(args)
    except (PolicyLoadError, ValueError, RuntimeError) as exc:
        print(f"pd-eval: {exc}", file=sys.stderr)
        return 2
    name = args.name or name
    fo = fuel_optimal_ratios(ro, args.fuel_optimal) if args.fuel_optimal > 0 else None
    summary = summarise(ro, fo)
    compared = {n: summarise(r) for n, (_spec, r) in others.items()}
    figures: dict[str, str] = {}
    if args.figures:
        figures = write_figures(args, actor, name, spec, ro, others)
    if args.json:
        print(to_json(summary, name=name, seed=args.seed, figures=figures, compare=compared))
    else:
        print(format_report(summary, name, args.seed))
        if compared:
            print("\n" + table7_blocks({name: summary, **compared}))
            for n, c in compared.items():
                if "layer_steps" in c:
                    print(f"runtime layer of {n}: {describe_layer(c)}")
        for k, v in figures.items():
            print(f"figure {k}: {v}")
    return 0


def _compared(args: argparse.Namespace) -> dict[str, tuple[str, Rollouts]]:
    """Every --compare agent flown on the same episodes: name -> (spec, rollouts)."""
    out = {}
    for other in args.compare:
        other_name, other_spec = _split(other)
        out[other_name] = (other_spec, _rollouts(args, other_spec, build(other_spec).actor))
    return out


def _rollouts(args: argparse.Namespace, spec: str, actor: Any) -> Rollouts:
    """The nominal evaluation, here (keeping episode 0's path) or as Ray shards."""
    if not args.ray:
        return rollout(
            actor,
            args.episodes,
            args.seed,
            disturbance=not args.no_disturbance,
            keep_trajectories=1,
        )
    flown = _fly_campaign(args, {"agent": spec}, [NOMINAL])
    ro = flown[NOMINAL.name]["agent"]
    if args.figures:  # Fig. 6 needs episode 0's path, which shards do not return
        first = rollout(
            actor, 1, args.seed, disturbance=not args.no_disturbance, keep_trajectories=1
        )
        ro.trajectories, ro.actions = first.trajectories, first.actions
    return ro


def _fly_campaign(
    args: argparse.Namespace, agents: dict[str, str], scenarios: list[Dispersions]
) -> dict[str, dict[str, Rollouts]]:
    common = {"disturbance": not args.no_disturbance, "progress": not args.no_progress}
    if args.ray:
        from pd_core.experiments.ray_campaign import run_campaign_ray  # imports Ray: only for --ray

        return run_campaign_ray(
            agents,
            scenarios,
            args.episodes,
            args.seed,
            shards=args.shards,
            address=args.address,
            **common,
        )
    return run_campaign(agents, scenarios, args.episodes, args.seed, **common)


def campaign_main(args: argparse.Namespace, spec: str, name: str) -> int:
    """Every scenario of --dispersions for the model and every --compare agent: one table."""
    scenarios = load_scenarios(args.dispersions)
    agents = {name: spec}
    for other in args.compare:
        other_name, other_spec = _split(other)
        build(other_spec)  # refuse a bad file before flying anything
        agents[other_name] = other_spec
    flown = _fly_campaign(args, agents, scenarios)
    reach = None
    if args.reachability:
        reach = reachability(flown, scenarios, args.seed, progress=not args.no_progress)
    t = table(flown, scenarios, list(agents), args.seed, args.episodes, reach)
    out = Path(args.out or f"out/campaign-{time.strftime('%Y%m%d-%H%M%S')}")
    t["files"] = {
        "json": str(out / "campaign.json"),
        "png": str(plots.campaign_summary(t, _mkdir(out) / "campaign.png")),
    }
    write_json(t, out / "campaign.json")
    if args.json:
        print(json.dumps(t, indent=2))
    else:
        print(format_table(t))
        print(f"\nwrote {t['files']['json']} and {t['files']['png']}")
    return 0


def _mkdir(p: Path) -> Path:
    p.mkdir(parents=True, exist_ok=True)
    return p


def training_logs(args: argparse.Namespace, specs: dict[str, str]) -> dict[str, Path]:
    """Fig. 5's logs: --training-log, and `<model>.episodes.csv` shipped beside a model file."""
    logs = {n: Path(p) for n, p in (_split(s) for s in args.training_log)}
    for n, spec in specs.items():
        csv = Path(spec).with_suffix(".episodes.csv")
        if n not in logs and "controller:" not in spec and csv.is_file():
            logs[n] = csv
    return logs


def write_figures(
    args: argparse.Namespace,
    actor: Any,
    name: str,
    spec: str,
    ro: Rollouts,
    others: dict[str, tuple[str, Rollouts]],
) -> dict[str, str]:
    out = Path(args.figures)
    out.mkdir(parents=True, exist_ok=True)
    figs: dict[str, str] = {}
    path, acts = ro.trajectories[0], ro.actions[0]
    thrust = actor.thrust(0) * 0 if len(acts) == 0 else np.array([actor.thrust(a) for a in acts])
    figs["fig6"] = str(
        plots.fig6_trajectory(path, thrust, DT_S, out / "fig6_trajectory.png", f"Fig. 6: {name}")
    )
    finals = {name: ro.final_states, **{n: r.final_states for n, (_s, r) in others.items()}}
    figs["fig7"] = str(plots.fig7_final_distributions(finals, out / "fig7_final_states.png"))
    figs["fig8"] = str(
        plots.fig8_initial_j_vs_final_i(
            ro.initial_states, ro.final_states, out / "fig8_j0_vs_final_i.png", name
        )
    )
    logs = training_logs(args, {name: spec, **{n: s for n, (s, _r) in others.items()}})
    if logs:
        figs["fig5"] = str(plots.fig5_cumulative_successes(logs, out / "fig5_successes.png"))
    (out / "figures.json").write_text(json.dumps(figs, indent=2) + "\n")
    return figs


if __name__ == "__main__":
    sys.exit(main())
