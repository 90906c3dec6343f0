"""Campaigns sharded over Ray: each shard (agent, scenario, episode range) is one Ray task.

Shards are cut on multiples of the rollout chunk (`pd_core.experiments.campaign.episode_ranges`),
so the
merged result is exactly the unsharded one. A task whose worker dies is retried by Ray
(`max_retries`): a shard's result comes back once, from whichever attempt completed.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping
from typing import Any

import ray  # optional heavy dependency: imported only by the Ray code paths
from tqdm import tqdm

from pd_core.dispersions import Dispersions
from pd_core.episodes import CHUNK_EPISODES, Actor, Rollouts
from pd_core.experiments.campaign import Shard, fly_shard, merge, plan
from pd_core.ray_session import MAX_RETRIES, cluster_cpus, connect
from pd_core.runtime.build import AgentSpec, build


@functools.lru_cache(maxsize=8)
def _cached_actor(spec: str) -> Actor:
    """A worker loads a policy file once, however many shards it flies."""
    return build(spec).actor


def _fly_task(
    spec: AgentSpec,
    scenario: Dispersions,
    seed: int,
    shard: Shard,
    disturbance: bool,
    chunk: int,
) -> Rollouts:
    actor = _cached_actor(spec) if isinstance(spec, str) else build(spec).actor
    return fly_shard(actor, scenario, seed, shard, disturbance, chunk)


def default_shards(n_cells: int, episodes: int, chunk: int = CHUNK_EPISODES) -> int:
    """Shards per (agent, scenario): about 4 tasks per CPU of the cluster in all, for balance
    and progress, and no more than the chunks there are."""
    return max(1, min(math.ceil(4 * cluster_cpus() / n_cells), math.ceil(episodes / chunk)))


def run_campaign_ray(
    agents: Mapping[str, AgentSpec],
    scenarios: list[Dispersions],
    episodes: int,
    seed: int,
    disturbance: bool = True,
    shards: int | None = None,
    chunk: int = CHUNK_EPISODES,
    address: str | None = None,
    progress: bool = True,
    max_retries: int = MAX_RETRIES,
) -> dict[str, dict[str, Rollouts]]:
    """`pd_core.experiments.campaign.run_campaign` as Ray tasks: {scenario: {agent: Rollouts}},
    the same
    numbers. RayUnavailable if Ray cannot be started or joined."""
    connect(address)
    n = shards or default_shards(len(agents) * len(scenarios), episodes, chunk)
    todo = plan(agents, len(scenarios), episodes, n, chunk)
    task = ray.remote(num_cpus=1, max_retries=max_retries)(_fly_task)
    pending = {
        task.remote(agents[s.agent], scenarios[s.scenario], seed, s, disturbance, chunk): i
        for i, s in enumerate(todo)
    }
    results: list[Any] = [None] * len(todo)
    with tqdm(total=sum(s.episodes for s in todo), unit="ep", disable=not progress) as bar:
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            for ref in done:
                i = pending.pop(ref)
                results[i] = ray.get(ref)
                bar.update(todo[i].episodes)
    return merge(todo, results, scenarios)
