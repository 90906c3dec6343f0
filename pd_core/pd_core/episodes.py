"""The episode runner: seeded episodes of any agent in the vector env, and their summary.

Episode i of a run with seed s flies exactly what `PoweredDescentEnv` seeded with s + i flies
(the vector env's guarantee), with disturbances on, greedy actions, the same env factory as
training (`pd_core.vector_env.make_vector_env`), optionally under dispersions
(`pd_core.dispersions`). Nothing here imports torch: an actor is anything with
`act_batch(states (B, 7)) -> (B,)`, or `begin_episodes(n)` + `act_rows(states, rows)` for one
with memory per lander (`pd_core.runtime`). Evaluation, demonstrations, DAgger and training all
fly episodes through `rollout`; it sits below them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from pd_core.config import MAX_EPISODE_TIME_S, REWARD, RewardConfig
from pd_core.dispersions import Dispersions
from pd_core.runtime.decision import changed_count
from pd_core.vector_env import PoweredDescentVectorEnv, make_vector_env

SOFT_K_VELOCITY_MPS = -2.0  # soft landing: k-velocity at touchdown above this
# episodes flown at once by `rollout`; campaigns split on multiples of it (see `rollout`)
CHUNK_EPISODES = 1024


class Actor(Protocol):
    def act_batch(self, states: np.ndarray) -> np.ndarray: ...


@dataclass
class Rollouts:
    """Per-episode results of `rollout` (arrays over episodes)."""

    initial_states: np.ndarray  # (N, 7)
    final_states: np.ndarray  # (N, 7)
    landed: np.ndarray  # (N,) bool, the kappa condition of Eq. 12 at termination
    terminated: np.ndarray  # (N,) bool (False: out of time)
    steps: np.ndarray  # (N,)
    returns: np.ndarray  # (N,) undiscounted training reward
    trajectories: list[np.ndarray] = field(default_factory=list)  # states (T+1, 7), if kept
    actions: list[np.ndarray] = field(default_factory=list)  # actions (T,), if kept
    layer: dict[str, int] = field(default_factory=dict)
    """steps decided by each source of the runtime layer over these episodes
    (`pd_core.runtime.decision.SOURCES`); empty for an actor flown without one"""

    @property
    def fuel_kg(self) -> np.ndarray:
        return self.initial_states[:, 6] - self.final_states[:, 6]


def concat_rollouts(parts: Sequence[Rollouts]) -> Rollouts:
    """Rollouts of consecutive episode ranges, in order, as one."""
    cat = [np.concatenate([getattr(p, f) for p in parts]) for f in _ARRAY_FIELDS]
    paths = [t for p in parts for t in p.trajectories]
    acts = [a for p in parts for a in p.actions]
    layer: dict[str, int] = {}
    for p in parts:
        for k, v in p.layer.items():
            layer[k] = layer.get(k, 0) + v
    return Rollouts(*cat, paths, acts, layer)


_ARRAY_FIELDS = ("initial_states", "final_states", "landed", "terminated", "steps", "returns")


def rollout(
    actor: Actor,
    n_episodes: int,
    seed: int,
    disturbance: bool = True,
    max_time_s: float = MAX_EPISODE_TIME_S,
    reward_cfg: RewardConfig = REWARD,
    keep_trajectories: int = 0,
    initial_states: np.ndarray | None = None,
    *,
    dispersions: str | Dispersions | Sequence[Dispersions] = "",
    chunk: int = CHUNK_EPISODES,
    episode_seeds: Sequence[int] | None = None,
) -> Rollouts:
    """Fly episodes 0..n_episodes-1 (episode i: env seed seed + i, or episode_seeds[i]) with
    greedy actions.

    Episodes are flown `chunk` at a time in one vector env (memory stays bounded for 10^6
    episodes); the result does not depend on how the caller splits a campaign as long as the
    split falls on multiples of `chunk` (then every chunk is the same batch). Keeps the states
    and actions of the first `keep_trajectories` episodes.
    """
    if n_episodes < 1:
        raise ValueError(f"n_episodes must be >= 1, got {n_episodes}")
    env = None
    parts = []
    for start in range(0, n_episodes, chunk):
        n = min(chunk, n_episodes - start)
        if env is None or env.num_envs != n:
            env = make_vector_env(
                n,
                disturbance=disturbance,
                max_time_s=max_time_s,
                reward_cfg=reward_cfg,
                autoreset=False,
                dispersions=dispersions,
            )
        init = None if initial_states is None else initial_states[start : start + n]
        keep = max(0, min(keep_trajectories - start, n))
        seeds = (
            seed + start
            if episode_seeds is None
            else [int(s) for s in episode_seeds[start : start + n]]
        )
        parts.append(fly_episodes(actor, env, seeds, init, keep))
    return concat_rollouts(parts)


def fly_episodes(
    actor: Actor,
    env: PoweredDescentVectorEnv,
    seed: int | list[int],
    initial_states: np.ndarray | None = None,
    keep_trajectories: int = 0,
) -> Rollouts:
    """Fly one episode in each sub-env of `env` (made with autoreset=False), sub-env i with
    seed seed + i (or seed[i]); the actor sees the observed states of the landers still flying."""
    opts = None if initial_states is None else {"initial_state": initial_states}
    _, info = env.reset(seed=seed, options=opts)
    n = env.num_envs
    init = info["state"].copy()
    term = np.zeros(n, dtype=bool)
    landed = np.zeros(n, dtype=bool)
    ret = np.zeros(n)
    k = min(keep_trajectories, n)
    paths: list[list[np.ndarray]] = [[init[i].copy()] for i in range(k)]
    acts: list[list[int]] = [[] for _ in range(k)]
    observed = info["observed_state"]
    active = env.active
    actions = np.zeros(n, dtype=np.int64)
    rowwise = hasattr(
        actor, "act_rows"
    )  # an actor with memory per lander (pd_core.runtime.latency)
    if rowwise:
        actor.begin_episodes(n)
    elif hasattr(actor, "begin_episode"):  # an actor flown alone (an MPC: forget its plans)
        actor.begin_episode()
    counted = dict(getattr(actor, "counts", {}))
    while active.any():
        if rowwise:
            actions[active] = actor.act_rows(observed[active], np.flatnonzero(active))
        else:
            actions[active] = actor.act_batch(observed[active])
        _, r, te, _, info = env.step(actions)
        ret += r
        term |= te
        landed |= info["landed"]
        for i in np.flatnonzero(active[:k]):
            paths[i].append(info["state"][i].copy())
            acts[i].append(int(actions[i]))
        observed, active = info["observed_state"], info["active"]
    return Rollouts(
        init,
        info["state"].copy(),
        landed,
        term,
        env.steps.copy(),
        ret,
        [np.array(p) for p in paths],
        [np.array(a, dtype=np.int64) for a in acts],
        {k: v - counted[k] for k, v in getattr(actor, "counts", {}).items()},
    )


def final_quantities(ro: Rollouts) -> dict[str, np.ndarray]:
    f = ro.final_states
    return {
        "norm_ij_position_m": np.linalg.norm(f[:, 0:2], axis=1),
        "norm_ij_velocity_mps": np.linalg.norm(f[:, 3:5], axis=1),
        "k_velocity_mps": f[:, 5],
        "fuel_kg": ro.fuel_kg,
    }


def layer_changed_rate(ro: Rollouts) -> float | None:
    """Share of the steps flown on which the runtime layer changed the action (None: no layer)."""
    return changed_count(ro.layer) / max(sum(ro.layer.values()), 1) if ro.layer else None


def summarise(ro: Rollouts, fuel_optimal: dict[str, Any] | None = None) -> dict[str, Any]:
    """Table 7 rows (median, min, max), success and soft-landing rates, and fuel ratios."""
    q = final_quantities(ro)
    table = {
        k: {"median": float(np.median(v)), "min": float(np.min(v)), "max": float(np.max(v))}
        for k, v in q.items()
    }
    touchdown = ro.terminated
    out: dict[str, Any] = {
        "episodes": len(ro.landed),
        "table7": table,
        "success_rate": float(np.mean(ro.landed)),
        "soft_landing_rate": float(
            np.mean(touchdown & (q["k_velocity_mps"] > SOFT_K_VELOCITY_MPS))
        ),
        "out_of_time_rate": float(np.mean(~touchdown)),
        "mean_return": float(np.mean(ro.returns)),
        "median_steps": float(np.median(ro.steps)),
    }
    if ro.layer:
        out["layer_changed_rate"] = layer_changed_rate(ro)
        out["layer_steps"] = dict(ro.layer)
    if fuel_optimal is not None:
        out["fuel_optimal"] = fuel_optimal
    return out
