"""Evaluation of a policy or controller over seeded Table 3 episodes (Sec. 3.2, 4.4, Table 7).

Episode i of an evaluation with seed s flies exactly what `PoweredDescentEnv` seeded with s + i
flies (the vector env's guarantee), with disturbances on, greedy actions, the same env factory as
training (`pd_core.vector_env.make_vector_env`), optionally under dispersions
(`pd_core.dispersions`).
Nothing here imports torch: an actor is anything with `act_batch(states (B, 7)) -> (B,)`.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import Any, Protocol

import numpy as np

from pd_core.config import MAX_EPISODE_TIME_S, PAPER_TABLE7, REWARD, RewardConfig
from pd_core.dispersions import Dispersions
from pd_core.runtime.decision import changed_count, describe_counts
from pd_core.vector_env import PoweredDescentVectorEnv, make_vector_env

QUANTITIES = ("norm_ij_position_m", "norm_ij_velocity_mps", "k_velocity_mps", "fuel_kg")
LABELS = {
    "norm_ij_position_m": "Norm ij-position (m)",
    "norm_ij_velocity_mps": "Norm ij-velocity (m/s)",
    "k_velocity_mps": "k-velocity (m/s)",
    "fuel_kg": "Fuel (kg)",
}
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
    "CHUNK_EPISODES",
    "Rollouts",
    "concat_rollouts",
    "describe_layer",
    "fly_episodes",
    "final_quantities",
    "format_report",
    "fuel_optimal_ratios",
    "layer_changed_rate",
    "rollout",
    "summarise",
]
