"""Demonstrations flown by a closed-loop teacher (issue 10): `controller_demonstrations`
(`mpc_demonstrations` for the MPC teacher) are episodes flown by the receding-horizon teacher
(`pd_core.teachers.mpc`) or another controller in the disturbed environment (and any
dispersions), bare or behind the runtime layer, as 1-step transitions for
`pd_core.dqn.demo_memory`.

`map_chunks` spreads seeded chunks of fixed size over a process pool: chunk k always holds the same
episodes (seeds seed + k * chunk ...) flown by a fresh teacher, so the result does not depend on
the number of workers. Workers are spawned, not forked (the caller may hold torch threads). Given
a Ray `address`, the chunks run as Ray tasks instead (`pd_core.ray_session`): the
same chunks, so the same result.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np

from pd_core import ocp
from pd_core.episodes import Rollouts, rollout
from pd_core.runtime.config import RuntimeConfig
from pd_core.runtime.layer import Runtime
from pd_core.teachers.registry import make_controller

DEMO_CHUNK_EPISODES = 25  # ours: episodes per pool task (small enough to balance 2 workers)


def map_chunks(
    fn: Callable[..., Any], tasks: Sequence[tuple], workers: int | None, address: str = ""
) -> list[Any]:
    """fn(*task) for every task, in order: as Ray tasks when `address` is given (auto,
    host:port, ray://host:port, or local), else in a spawned process pool unless workers <= 1."""
    if address:
        from pd_core.ray_session import map_tasks  # imports Ray: only with an address

        return map_tasks(fn, tasks, address)
    n = (os.cpu_count() or 1) if workers is None else workers
    if n <= 1 or len(tasks) <= 1:
        return [fn(*t) for t in tasks]
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=min(n, len(tasks)), mp_context=ctx) as pool:
        return list(pool.map(fn, *zip(*tasks, strict=True)))


def rollout_steps(ro: Rollouts, first_episode: int = 0) -> dict[str, np.ndarray]:
    """1-step transitions of every kept trajectory of `ro` (true states; episode ids from
    `first_episode`): states, actions, next_states, dones, episode, and landed per episode."""
    s, a, nx, d, ep = [], [], [], [], []
    for i, (path, acts) in enumerate(zip(ro.trajectories, ro.actions, strict=True)):
        t = len(acts)
        s.append(path[:-1])
        nx.append(path[1:])
        a.append(acts)
        done = np.zeros(t, dtype=bool)
        done[-1] = bool(ro.terminated[i])
        d.append(done)
        ep.append(np.full(t, first_episode + i))
    return {
        "states": np.concatenate(s),
        "actions": np.concatenate(a).astype(np.int64),
        "next_states": np.concatenate(nx),
        "dones": np.concatenate(d),
        "episode": np.concatenate(ep).astype(np.int64),
        "landed": ro.landed.copy(),
    }


class FractionRecorder:
    """An actor that flies `inner` and records, step by step, the vertical thrust fraction the
    runtime layer counts on for the rows it is asked about (`Runtime.step_rows` hands it over
    before each `act_batch`; passed on to an `inner` that takes it too)."""

    takes_thrust_fraction = True

    def __init__(self, inner: Any) -> None:
        self.inner = inner
        self.name = getattr(inner, "name", "controller")
        self.steps: list[np.ndarray] = []

    def take_thrust_fraction(self, fraction: np.ndarray) -> None:
        self.steps.append(np.array(fraction, dtype=float).reshape(-1))
        if getattr(self.inner, "takes_thrust_fraction", False):
            self.inner.take_thrust_fraction(fraction)

    def begin_episode(self) -> None:
        """Every lander starts a new episode: `inner` forgets its memory (the fractions stay)."""
        begin = getattr(self.inner, "begin_episode", None)
        if begin is not None:
            begin()

    def act_batch(self, states: np.ndarray) -> np.ndarray:
        return self.inner.act_batch(states)

    def per_episode(self, lengths: Sequence[int]) -> list[np.ndarray]:
        """The fractions of each episode (T_i,) of a `fly_episodes` batch whose episodes flew
        `lengths` steps: at step t the actor is asked about the episodes still flying, in
        order (those with more than t steps)."""
        lengths = np.asarray(lengths)
        out = [np.empty(int(t)) for t in lengths]
        for t, f in enumerate(self.steps):
            for j, i in enumerate(np.flatnonzero(lengths > t)):
                out[i][t] = f[j]
        return out


def _fly_chunk(
    controller: str,
    n: int,
    seed: int,
    first_episode: int,
    dispersions: Any,
    initial_states: np.ndarray | None,
    episode_seeds: np.ndarray | None = None,
    behind_layer: bool = False,
    layer_settings: str = "",
) -> dict[str, np.ndarray]:
    """Transitions of episodes first_episode .. + n - 1 (env seeds seed .., or episode_seeds)
    of a fresh controller (behind the default runtime layer if `behind_layer`, with
    `layer_settings` changed; then with "fraction", the thrust fraction the layer counted on at
    each step)."""
    ctl = make_controller(controller)
    recorder = FractionRecorder(ctl) if behind_layer and layer_settings else None
    config = RuntimeConfig().with_settings(layer_settings) if layer_settings else RuntimeConfig()
    actor = recorder or ctl
    ro = rollout(
        Runtime(actor, config) if behind_layer else ctl,
        n,
        seed,
        keep_trajectories=n,
        initial_states=initial_states,
        dispersions=dispersions,
        episode_seeds=episode_seeds,
        chunk=n,
    )
    out = rollout_steps(ro, first_episode)
    if recorder is not None:
        out["fraction"] = np.concatenate(recorder.per_episode([len(a) for a in ro.actions]))
    return out


def controller_demonstrations(
    controller: str,
    n_episodes: int,
    seed: int,
    *,
    dispersions: Any = "",
    initial_states: np.ndarray | None = None,
    workers: int | None = None,
    chunk: int = DEMO_CHUNK_EPISODES,
    episode_seeds: np.ndarray | None = None,
    behind_layer: bool = False,
    address: str = "",
    layer_settings: str = "",
) -> dict[str, np.ndarray]:
    """Physical 1-step transitions of a controller of `pd_core.teachers.zemzev` (the MPC teacher
    `mpc-fuel`/`mpc-energy`, or `zemzev`) flying episodes 0..n_episodes-1 (episode i: env seed
    seed + i, disturbances on; initial state sampled from Table 3 or row i of `initial_states`):
    states, actions, next_states, dones, episode, landed (per episode) and success_rate.
    `dispersions` and `episode_seeds` (env seed of each episode instead of seed + i) as
    `pd_core.episodes.rollout`; `workers` None = every core. `behind_layer`: the
    controller flies behind the default runtime layer (`pd_core.runtime.Runtime`), as a
    student trained on the demonstrations will fly: the actions are the ones flown;
    `layer_settings` change that layer (`RuntimeConfig.with_settings`) and add "fraction" (N,),
    the vertical thrust fraction it counted on at each step. `address`: the chunks run on Ray
    there instead (`map_chunks`)."""
    if n_episodes < 1:
        raise ValueError(f"n_episodes must be >= 1, got {n_episodes}")
    make_controller(controller)  # an unknown name fails here, in the caller's process
    init = None if initial_states is None else np.asarray(initial_states, dtype=float)
    tasks = [
        (
            controller,
            min(chunk, n_episodes - k),
            seed + k,
            k,
            dispersions,
            None if init is None else init[k : k + chunk],
            None if episode_seeds is None else np.asarray(episode_seeds)[k : k + chunk],
            behind_layer,
            layer_settings,
        )
        for k in range(0, n_episodes, chunk)
    ]
    parts = map_chunks(_fly_chunk, tasks, workers, address)
    out = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    out["success_rate"] = np.array(float(np.mean(out["landed"])))
    return out


def mpc_demonstrations(
    n_episodes: int, seed: int, objective: str = "fuel", **kw: Any
) -> dict[str, np.ndarray]:
    """`controller_demonstrations` of the MPC teacher with this objective (Eq. 4 or fuel)."""
    if objective not in ocp.OBJECTIVES:
        raise ValueError(f"objective must be one of {ocp.OBJECTIVES}, got {objective!r}")
    return controller_demonstrations(f"mpc-{objective}", n_episodes, seed, **kw)
