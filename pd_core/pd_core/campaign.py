"""Monte Carlo campaigns: every dispersion scenario for every agent, one table.

A campaign is (agents) x (scenarios) x (episodes 0..N-1, episode i on env seed s + i). It is cut
into shards along the episode index on multiples of `CHUNK_EPISODES` (each chunk is flown as one
batch), so any split into shards, in one process or as Ray tasks (`pd_core.ray_campaign`),
gives exactly the unsharded numbers. Nothing here imports torch (a policy file loads it) or Ray.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from pd_core.controllers import make_controller
from pd_core.dispersions import Dispersions
from pd_core.evaluate import (
    CHUNK_EPISODES,
    SOFT_K_VELOCITY_MPS,
    Actor,
    Rollouts,
    concat_rollouts,
    rollout,
)
from pd_core.policy import load_policy

# An agent: a policy file, "controller:<name>", or a picklable factory returning an actor.
AgentSpec = str | Callable[[], Actor]
METRICS = (
    ("success_rate", "success %", 100.0, ".1f"),
    ("soft_landing_rate", "soft %", 100.0, ".1f"),
    ("miss_median_m", "miss p50 m", 1.0, ".2f"),
    ("miss_p99_m", "miss p99 m", 1.0, ".2f"),
    ("k_velocity_worst_mps", "worst vk m/s", 1.0, ".2f"),
    ("fuel_median_kg", "fuel p50 kg", 1.0, ".1f"),
)


def load_actor(spec: AgentSpec) -> tuple[Actor, str]:
    """(actor, label) of a policy file, `controller:<name>` or a factory."""
    if callable(spec):
        return spec(), getattr(spec, "__name__", "agent")
    if spec.startswith("controller:"):
        name = spec.split(":", 1)[1]
        return make_controller(name), f"controller {name}"
    return load_policy(spec), Path(spec).stem


@dataclass(frozen=True)
class Shard:
    """Episodes [start, stop) of one agent under one scenario."""

    agent: str
    scenario: int  # index into the campaign's scenarios
    start: int
    stop: int

    @property
    def episodes(self) -> int:
        return self.stop - self.start


def episode_ranges(episodes: int, shards: int, chunk: int = CHUNK_EPISODES) -> list[range]:
    """At most `shards` contiguous ranges covering 0..episodes-1, cut on multiples of `chunk`."""
    chunks = math.ceil(episodes / chunk)
    n = max(1, min(shards, chunks))
    bounds = [round(k * chunks / n) * chunk for k in range(n)] + [episodes]
    return [
        range(a, min(b, episodes))
        for a, b in zip(bounds[:-1], bounds[1:], strict=True)
        if a < min(b, episodes)
    ]


def plan(
    agents: Iterable[str], n_scenarios: int, episodes: int, shards: int, chunk: int = CHUNK_EPISODES
) -> list[Shard]:
    return [
        Shard(a, k, r.start, r.stop)
        for a in agents
        for k in range(n_scenarios)
        for r in episode_ranges(episodes, shards, chunk)
    ]


def fly_shard(
    actor: Actor,
    scenario: Dispersions,
    seed: int,
    shard: Shard,
    disturbance: bool = True,
    chunk: int = CHUNK_EPISODES,
    on_chunk: Callable[[int], None] | None = None,
) -> Rollouts:
    """Episodes of `shard` (episode i on seed seed + i), one chunk at a time."""
    parts = []
    for a in range(shard.start, shard.stop, chunk):
        n = min(chunk, shard.stop - a)
        parts.append(
            rollout(actor, n, seed + a, disturbance=disturbance, dispersions=scenario, chunk=chunk)
        )
        if on_chunk is not None:
            on_chunk(n)
    return concat_rollouts(parts)


def metrics(ro: Rollouts) -> dict[str, float]:
    """One cell of the campaign table."""
    f = ro.final_states
    miss = np.linalg.norm(f[:, 0:2], axis=1)
    return {
        "episodes": len(ro.landed),
        "success_rate": float(np.mean(ro.landed)),
        "soft_landing_rate": float(np.mean(ro.terminated & (f[:, 5] > SOFT_K_VELOCITY_MPS))),
        "miss_median_m": float(np.median(miss)),
        "miss_p99_m": float(np.percentile(miss, 99)),
        "k_velocity_worst_mps": float(np.min(f[:, 5])),
        "fuel_median_kg": float(np.median(ro.fuel_kg)),
        "out_of_time_rate": float(np.mean(~ro.terminated)),
    }


def merge(
    shards: list[Shard], results: list[Rollouts], scenarios: list[Dispersions]
) -> dict[str, dict[str, Rollouts]]:
    """{scenario name: {agent: Rollouts in episode order}} from shard results (any order)."""
    cells: dict[tuple[int, str], list[tuple[int, Rollouts]]] = {}
    for sh, ro in zip(shards, results, strict=True):
        cells.setdefault((sh.scenario, sh.agent), []).append((sh.start, ro))
    out: dict[str, dict[str, Rollouts]] = {}
    for (k, agent), parts in cells.items():
        parts.sort(key=lambda p: p[0])
        out.setdefault(scenarios[k].name, {})[agent] = concat_rollouts([p[1] for p in parts])
    return out


def run_campaign(
    agents: Mapping[str, AgentSpec],
    scenarios: list[Dispersions],
    episodes: int,
    seed: int,
    disturbance: bool = True,
    shards: int = 1,
    chunk: int = CHUNK_EPISODES,
    progress: bool = False,
) -> dict[str, dict[str, Rollouts]]:
    """The campaign in this process: {scenario: {agent: Rollouts}}."""
    todo = plan(agents, len(scenarios), episodes, shards, chunk)
    bar = _bar(sum(s.episodes for s in todo), progress)
    actors = {name: load_actor(spec)[0] for name, spec in agents.items()}
    results = [
        fly_shard(actors[s.agent], scenarios[s.scenario], seed, s, disturbance, chunk, bar.update)
        for s in todo
    ]
    bar.close()
    return merge(todo, results, scenarios)


def _bar(total: int, enabled: bool) -> Any:
    return tqdm(total=total, unit="ep", disable=not enabled, smoothing=0.1)


def table(
    flown: dict[str, dict[str, Rollouts]],
    scenarios: list[Dispersions],
    agents: list[str],
    seed: int,
    episodes: int,
) -> dict[str, Any]:
    """The campaign as JSON-ready data: scenarios, agents and a metrics cell for each pair."""
    return {
        "seed": seed,
        "episodes": episodes,
        "agents": list(agents),
        "scenarios": [d.to_dict() for d in scenarios],
        "results": {d.name: {a: metrics(flown[d.name][a]) for a in agents} for d in scenarios},
        "mean_success_rate": {
            a: float(np.mean([metrics(flown[d.name][a])["success_rate"] for d in scenarios]))
            for a in agents
        },
    }


def format_table(t: dict[str, Any]) -> str:
    """Scenario x agent text table."""
    width = 14
    head = f"{'scenario':<14}{'agent':<18}" + "".join(f"{m[1]:>{width}}" for m in METRICS)
    lines = [
        f"pd-eval campaign: {t['episodes']} episodes per scenario and agent, seed {t['seed']} "
        "(episode i on seed + i)",
        "",
        head,
        "-" * len(head),
    ]
    for d in t["scenarios"]:
        for a in t["agents"]:
            cell = t["results"][d["name"]][a]
            vals = "".join(f"{cell[k] * s:>{width}{fmt}}" for k, _, s, fmt in METRICS)
            lines.append(f"{d['name']:<14}{a:<18}{vals}")
    lines.append("")
    for a, v in t["mean_success_rate"].items():
        lines.append(f"mean success over the campaign, {a}: {100 * v:.2f} %")
    return "\n".join(lines)


def write_json(t: dict[str, Any], path: str | Path) -> Path:
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(json.dumps(t, indent=2) + "\n")
    return p


__all__ = [
    "AgentSpec",
    "Shard",
    "episode_ranges",
    "fly_shard",
    "format_table",
    "load_actor",
    "merge",
    "metrics",
    "plan",
    "run_campaign",
    "table",
    "write_json",
]
