"""Monte Carlo campaigns: every dispersion scenario for every agent, one table.

A campaign is (agents) x (scenarios) x (episodes 0..N-1, episode i on env seed s + i). It is cut
into shards along the episode index on multiples of `CHUNK_EPISODES` (each chunk is flown as one
batch), so any split into shards, in one process or as Ray tasks
(`pd_core.experiments.ray_campaign`),
gives exactly the unsharded numbers. Nothing here imports torch (a policy file loads it) or Ray.

With `reachability`, the episodes some agent failed are judged by
`pd_core.experiments.reachability`, and the
table adds per scenario the episodes proven out of reach and per agent the success rate over the
others (issue 10: a scenario's 99 % target excludes only what no thrust schedule can land).
"""

from __future__ import annotations

import json
import math
from collections import Counter
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from pd_core.dispersions import Dispersions
from pd_core.episodes import (
    CHUNK_EPISODES,
    SOFT_K_VELOCITY_MPS,
    Actor,
    Rollouts,
    concat_rollouts,
    layer_changed_rate,
    rollout,
)
from pd_core.experiments.reachability import ScenarioReach, campaign_reachability, failed_episodes
from pd_core.reward import missed_limits
from pd_core.runtime.build import AgentSpec, build

METRICS = (
    ("success_rate", "success %", 100.0, ".1f"),
    ("soft_landing_rate", "soft %", 100.0, ".1f"),
    ("miss_median_m", "miss p50 m", 1.0, ".2f"),
    ("miss_p99_m", "miss p99 m", 1.0, ".2f"),
    ("k_velocity_worst_mps", "worst vk m/s", 1.0, ".2f"),
    ("fuel_median_kg", "fuel p50 kg", 1.0, ".1f"),
    ("layer_changed_rate", "layer %", 100.0, ".1f"),
)
REACH_HEAD = ("out of reach", "success % of reachable")
# Failed episodes listed per cell: in campaign.json (enough for complete pairs in
# bench/campaign_sign_test.py down to 90 % success at 2000 episodes a cell), and in the table.
LISTED_FAILURES_JSON = 200
LISTED_FAILURES_TEXT = 3


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
        "layer_changed_rate": layer_changed_rate(ro),
    }


def failures(ro: Rollouts, seed: int, limit: int = LISTED_FAILURES_JSON) -> dict[str, Any]:
    """The cell's failed episodes, enough to replay each (episode i flies on env seed seed + i,
    so `--episodes 1 --seed <its seed>` flies it again) and to see how it failed: off the pad
    (Eq. 12's 5 m), too fast (2 m/s) or out of time; the first `limit` in detail (`listed`),
    every one by index (`episodes`), so two cells pair completely."""
    f = ro.final_states
    miss = np.linalg.norm(f[:, 0:2], axis=1)
    speed = np.linalg.norm(f[:, 3:6], axis=1)
    off, fast = missed_limits(f[:, 0:3], f[:, 3:6])
    idx = np.flatnonzero(~ro.landed)
    listed = []
    for i in idx[:limit]:
        why = [] if ro.terminated[i] else ["out of time"]
        if ro.terminated[i] and off[i]:
            why.append("off the pad")
        if ro.terminated[i] and fast[i]:
            why.append("too fast")
        listed.append(
            {
                "episode": int(i),
                "seed": seed + int(i),
                "outcome": ", ".join(why),
                "miss_m": round(float(miss[i]), 3),
                "speed_mps": round(float(speed[i]), 3),
                "k_velocity_mps": round(float(f[i, 5]), 3),
            }
        )
    return {"count": int(idx.size), "episodes": idx.tolist(), "listed": listed}


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
    """The campaign in this process: {scenario: {agent: Rollouts}}, each agent built once
    (`pd_core.runtime.build`) and flown on every scenario."""
    todo = plan(agents, len(scenarios), episodes, shards, chunk)
    bar = _bar(sum(s.episodes for s in todo), progress)
    actors = {name: build(spec).actor for name, spec in agents.items()}
    results = [
        fly_shard(actors[s.agent], scenarios[s.scenario], seed, s, disturbance, chunk, bar.update)
        for s in todo
    ]
    bar.close()
    return merge(todo, results, scenarios)


def _bar(total: int, enabled: bool) -> Any:
    return tqdm(total=total, unit="ep", disable=not enabled, smoothing=0.1)


def reachability(
    flown: dict[str, dict[str, Rollouts]],
    scenarios: list[Dispersions],
    seed: int,
    progress: bool = False,
) -> dict[str, ScenarioReach]:
    """{scenario: verdicts on the episodes some agent failed}
    (`pd_core.experiments.reachability`)."""
    bar = _bar(sum(len(failed_episodes(flown[d.name])) for d in scenarios), progress)
    out = campaign_reachability(flown, scenarios, seed, on_episode=lambda: bar.update(1))
    bar.close()
    return out


def table(
    flown: dict[str, dict[str, Rollouts]],
    scenarios: list[Dispersions],
    agents: list[str],
    seed: int,
    episodes: int,
    reach: Mapping[str, ScenarioReach] | None = None,
) -> dict[str, Any]:
    """The campaign as JSON-ready data: scenarios, agents and a metrics cell for each pair;
    with `reach`, also `reachability` per scenario and the success over reachable episodes."""
    results = {d.name: {a: metrics(flown[d.name][a]) for a in agents} for d in scenarios}
    for d in scenarios:
        for a in agents:
            results[d.name][a]["failed_episodes"] = failures(flown[d.name][a], seed)
    t = {
        "seed": seed,
        "episodes": episodes,
        "agents": list(agents),
        "scenarios": [d.to_dict() for d in scenarios],
        "results": results,
        "mean_success_rate": {
            a: float(np.mean([results[d.name][a]["success_rate"] for d in scenarios]))
            for a in agents
        },
    }
    if reach is None:
        return t
    t["reachability"] = {}
    for d in scenarios:
        r = reach[d.name]
        ok = np.ones(len(next(iter(flown[d.name].values())).landed), dtype=bool)
        ok[r.out_of_reach] = False
        for a in agents:
            landed = flown[d.name][a].landed[ok]
            results[d.name][a]["episodes_reachable"] = int(ok.sum())
            results[d.name][a]["success_rate_reachable"] = (
                float(np.mean(landed)) if len(landed) else None
            )
        t["reachability"][d.name] = {
            "checked_episodes": len(r.checked),
            "out_of_reach": len(r.out_of_reach),
            "out_of_reach_episodes": r.out_of_reach,
            "undecided_episodes": r.undecided,
            "plans": dict(Counter(v.plan or v.status for v in r.verdicts.values())),
            "evidence": {str(i): r.verdicts[i].to_dict() for i in r.out_of_reach + r.undecided},
        }
    t["mean_success_rate_reachable"] = {
        a: _mean_of_some([results[d.name][a]["success_rate_reachable"] for d in scenarios])
        for a in agents
    }
    return t


def format_table(t: dict[str, Any]) -> str:
    """Scenario x agent text table (with the reachability columns when the table has them)."""
    width = 14
    reach = t.get("reachability")
    # long names (a YAML campaign's, a --compare label) widen their column instead of running on
    sw = max([14] + [len(d["name"]) + 2 for d in t["scenarios"]])
    aw = max([18] + [len(a) + 2 for a in t["agents"]])
    head = f"{'scenario':<{sw}}{'agent':<{aw}}" + "".join(f"{m[1]:>{width}}" for m in METRICS)
    if reach is not None:
        head += f"{REACH_HEAD[0]:>{width}}{REACH_HEAD[1]:>24}"
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
            vals = "".join(_cell(cell.get(k), s, width, fmt) for k, _, s, fmt in METRICS)
            if reach is not None:
                rate = cell["success_rate_reachable"]
                vals += f"{reach[d['name']]['out_of_reach']:>{width}d}"
                vals += f"{'-' if rate is None else f'{100 * rate:.1f}':>24}"
            lines.append(f"{d['name']:<{sw}}{a:<{aw}}{vals}")
    lines.append("")
    for a, v in t["mean_success_rate"].items():
        lines.append(f"mean success over the campaign, {a}: {100 * v:.2f} %")
    lines += _failure_lines(t)
    if reach is not None:
        for a, v in t["mean_success_rate_reachable"].items():
            rate = "-" if v is None else f"{100 * v:.2f} %"
            lines.append(f"mean success over the reachable episodes, {a}: {rate}")
        lines += [
            "",
            "reachability of the episodes some agent failed (pd_core.experiments.reachability):",
        ]
        for name, r in reach.items():
            lines.append(
                f"  {name}: {r['checked_episodes']} judged, {r['out_of_reach']} out of reach "
                f"{_some(r['out_of_reach_episodes'])}, {len(r['undecided_episodes'])} undecided "
                f"{_some(r['undecided_episodes'])}"
            )
    return "\n".join(lines)


def _cell(value: float | None, scale: float, width: int, fmt: str) -> str:
    """One number of the table, '-' where the cell has none (a layer share without a layer)."""
    return f"{'-':>{width}}" if value is None else f"{value * scale:>{width}{fmt}}"


def _failure_lines(t: dict[str, Any], n: int = LISTED_FAILURES_TEXT) -> list[str]:
    """A few failed episodes per cell, each with the seed that flies it again."""
    lines = []
    for d in t["scenarios"]:
        for a in t["agents"]:
            failed = t["results"][d["name"]][a].get("failed_episodes")
            if not failed or not failed["count"]:
                continue
            shown = "; ".join(
                f"seed {e['seed']} {e['outcome']} ({e['miss_m']:.2f} m, {e['speed_mps']:.2f} m/s)"
                for e in failed["listed"][:n]
            )
            more = f"; {failed['count'] - n} more in the JSON" if failed["count"] > n else ""
            lines.append(f"  {d['name']} / {a}: {failed['count']} failed: {shown}{more}")
    if lines:
        lines = [
            "",
            "failed episodes (fly one again: --dispersions <scenario> --episodes 1 --seed <seed>):",
        ] + lines
    return lines


def _mean_of_some(values: list[float | None]) -> float | None:
    """Mean of the values that are not None (None if all are)."""
    v = [x for x in values if x is not None]
    return float(np.mean(v)) if v else None


def _some(idx: list[int], n: int = 12) -> str:
    """[i, j, ...] of at most n episode indices."""
    more = f", ... ({len(idx) - n} more)" if len(idx) > n else ""
    return "[" + ", ".join(map(str, idx[:n])) + more + "]"


def write_json(t: dict[str, Any], path: str | Path) -> Path:
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(json.dumps(t, indent=2) + "\n")
    return p


__all__ = [
    "Shard",
    "episode_ranges",
    "failures",
    "fly_shard",
    "format_table",
    "merge",
    "metrics",
    "plan",
    "reachability",
    "run_campaign",
    "table",
    "write_json",
]
