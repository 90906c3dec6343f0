"""DAgger labels (issue 32): the teacher's action on every state the student decides on.

The student (a policy file) flies episodes behind its runtime layer under the training
dispersions. Beside it, in shadow, the teacher (a controller of `pd_core.teachers.registry`) is
asked for its action on the very state the network is asked on (the layer's predicted state);
the teacher never flies, and an MPC teacher re-plans warm from state to state as along its own
flight. Each label becomes a one-step demonstration through the known dynamics (no
disturbance, the nominal engine): the state, the teacher's action and the state that action
leads to, so the DQfD memory's TD and margin losses take it like any other demonstration.

With `noise` > 0 the student flies a uniformly random action instead of its own on that share
of its steps (noise injection, as DART: Laskey et al. 2017), so that the labelled states include
the recoveries from its own errors that a greedy student seldom needs (the teacher still labels
every state; `proposed` stays the network's own choice). The random draws are seeded by each
chunk's first env seed.

Chunks of `LABEL_CHUNK_EPISODES` episodes (chunk k: env seeds seed + k * chunk ...) run on a
spawned process pool, or as Ray tasks given an address (`map_chunks`), so the labels do not
depend on the number of workers or where they run.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pd_core.actions import DEFAULT_ACTIONS
from pd_core.config import DT_S
from pd_core.demonstrations.teacher_flown import map_chunks
from pd_core.episodes import rollout
from pd_core.lander import transition
from pd_core.runtime.layer import Runtime
from pd_core.runtime.policy_file import load_policy
from pd_core.teachers.registry import make_controller

LABEL_CHUNK_EPISODES = 25  # ours: episodes per pool task (as the demonstrations)


class ShadowTeacher:
    """Actor that flies the student's actions and records the teacher's on the same states,
    and the vertical thrust fraction the runtime layer counts on for them (handed on to the
    student and the teacher where they take it: `Runtime.step_rows`)."""

    takes_thrust_fraction = True

    def __init__(
        self, student: Any, teacher: Any, noise: float = 0.0, rng: np.random.Generator | None = None
    ) -> None:
        self.student = student
        self.teacher = teacher
        self.noise = noise
        self.rng = rng or np.random.default_rng(0)
        self.name = getattr(student, "name", "student")
        self.states: list[np.ndarray] = []
        self.labels: list[np.ndarray] = []
        self.proposed: list[np.ndarray] = []
        self.flown: list[np.ndarray] = []
        self.fractions: list[np.ndarray] = []
        self._fraction: np.ndarray | None = None

    def take_thrust_fraction(self, fraction: np.ndarray) -> None:
        self._fraction = np.array(fraction, dtype=float).reshape(-1)
        for actor in (self.student, self.teacher):
            if getattr(actor, "takes_thrust_fraction", False):
                actor.take_thrust_fraction(self._fraction)

    def begin_episode(self) -> None:
        """Every lander starts a new episode: the student and the teacher forget their memory."""
        for actor in (self.student, self.teacher):
            begin = getattr(actor, "begin_episode", None)
            if begin is not None:
                begin()

    def act_batch(self, states: np.ndarray) -> np.ndarray:
        s = np.array(states, dtype=float).reshape(-1, 7)
        f, self._fraction = self._fraction, None
        self.fractions.append(f if f is not None and len(f) == len(s) else np.ones(len(s)))
        own = np.asarray(self.student.act_batch(s), dtype=np.int64).reshape(-1)
        self.states.append(s)
        self.labels.append(np.asarray(self.teacher.act_batch(s), dtype=np.int64).reshape(-1))
        self.proposed.append(own)
        if self.noise > 0.0:
            swap = self.rng.random(len(own)) < self.noise
            own = np.where(swap, self.rng.integers(0, DEFAULT_ACTIONS.n, len(own)), own)
        self.flown.append(own)
        return own


def _label_chunk(
    policy_path: str,
    teacher: str,
    n: int,
    seed: int,
    dispersions: Any,
    noise: float = 0.0,
    layer_settings: str = "",
) -> dict[str, np.ndarray]:
    """Labels of episodes seed .. seed + n - 1 flown by the student behind the default layer
    (with `layer_settings` changed)."""
    runtime = load_policy(policy_path, layer="always")
    if layer_settings:
        config = runtime.config.with_settings(layer_settings)
        runtime = Runtime(runtime.actor, config, runtime.actions, runtime.name, runtime.metadata)
    rng = np.random.default_rng(seed)
    shadow = ShadowTeacher(runtime.actor, make_controller(teacher), noise, rng)
    runtime.actor = shadow
    ro = rollout(runtime, n, seed, dispersions=dispersions, chunk=n)
    return {
        "states": np.concatenate(shadow.states),
        "labels": np.concatenate(shadow.labels),
        "proposed": np.concatenate(shadow.proposed),
        "flown": np.concatenate(shadow.flown),
        "fraction": np.concatenate(shadow.fractions),
        "landed": ro.landed,
    }


def student_labels(
    policy_path: str,
    teacher: str,
    n_episodes: int,
    seed: int,
    dispersions: Any = "",
    workers: int | None = None,
    chunk: int = LABEL_CHUNK_EPISODES,
    address: str = "",
    noise: float = 0.0,
    layer_settings: str = "",
) -> dict[str, np.ndarray]:
    """The teacher's labels on the states the student at `policy_path` decides on over
    episodes 0..n_episodes-1 (env seed seed + i, disturbances on, under `dispersions`):
    states (N, 7), labels (N,) the teacher's actions, proposed (N,) the network's own, flown
    (N,) the student's (its own, or random with `noise`) before its runtime layer, fraction
    (N,) the vertical thrust fraction that layer counted on, landed (n_episodes,) the
    student's outcomes. `workers` None = every core; `address`: on Ray there instead
    (`map_chunks`); `noise`: the share of steps flown with a random action; `layer_settings`:
    the student's layer changed from the default (`RuntimeConfig.with_settings`)."""
    if n_episodes < 1:
        raise ValueError(f"n_episodes must be >= 1, got {n_episodes}")
    if not 0.0 <= noise < 1.0:
        raise ValueError(f"noise must be in [0, 1), got {noise}")
    make_controller(teacher)  # an unknown name fails here, in the caller's process
    tasks = [
        (
            policy_path,
            teacher,
            min(chunk, n_episodes - k),
            seed + k,
            dispersions,
            noise,
            layer_settings,
        )
        for k in range(0, n_episodes, chunk)
    ]
    parts = map_chunks(_label_chunk, tasks, workers, address)
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def label_transitions(
    states: np.ndarray, labels: np.ndarray, fraction: np.ndarray | None = None
) -> dict[str, np.ndarray]:
    """One-step demonstrations of labels: states (N, 7), actions, next_states through the
    nominal dynamics with no disturbance, dones (touchdown) and one episode id per label.
    With `fraction` (N,) the states and next states carry it as an 8th column (the thrust
    fraction counted on, the same one step later)."""
    s = np.asarray(states, dtype=float).reshape(-1, 7)
    a = np.asarray(labels, dtype=np.int64).reshape(-1)
    nxt, _r, done, _ok = transition(s, DEFAULT_ACTIONS.thrust(a), np.zeros((len(a), 3)), DT_S)
    if fraction is not None:
        f = np.asarray(fraction, dtype=float).reshape(-1, 1)
        s, nxt = np.hstack([s, f]), np.hstack([nxt, f])
    return {
        "states": s,
        "actions": a,
        "next_states": nxt,
        "dones": np.asarray(done, dtype=bool),
        "episode": np.arange(len(a), dtype=np.int64),
    }
