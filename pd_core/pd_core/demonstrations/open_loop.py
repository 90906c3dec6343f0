"""Demonstration sets for the DQN (Sec. 2.3): discretised OCP episodes as replay transitions.

One compressed `.npz` holds the arrays of `DemoSet` plus a `metadata` JSON string that records
what the transitions mean (action space, thrust limits, dt, reward, state scale) so a loader built
from different constants refuses the file instead of learning from mislabelled actions.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from tqdm import tqdm

from pd_core import discretise as disc
from pd_core import ocp
from pd_core.config import DT_S, N_ACTIONS_PER_AXIS, REWARD, RL_THRUST, STATE_SCALE, TABLE1

FORMAT_VERSION = 1


class DemoSet(NamedTuple):
    """Transitions (s, a, r, s', done) of demonstration episodes, physical SI states."""

    states: np.ndarray  # (N, 7) float64
    actions: np.ndarray  # (N,) int64
    rewards: np.ndarray  # (N,) float64
    next_states: np.ndarray  # (N, 7) float64
    dones: np.ndarray  # (N,) bool, terminated (altitude < 0.01 m)
    episode: np.ndarray  # (N,) int64


def table1_initial_states() -> np.ndarray:
    """The 33 initial states of Sec. 3.1: all 32 corners of the 5 varying Table 1 variables, then
    the midpoint."""
    lo, hi = TABLE1.lo, TABLE1.hi
    varying = [i for i in range(7) if lo[i] != hi[i]]
    out = []
    for k in range(2 ** len(varying)):
        s = lo.copy()
        for bit, i in enumerate(varying):
            if (k >> (len(varying) - 1 - bit)) & 1:
                s[i] = hi[i]
        out.append(s)
    out.append(0.5 * (lo + hi))
    return np.array(out)


def code_metadata(n_per_axis: tuple[int, int, int] = N_ACTIONS_PER_AXIS) -> dict[str, Any]:
    """The constants a demo file must agree with."""
    return {
        "format_version": FORMAT_VERSION,
        "n_per_axis": list(n_per_axis),
        "thrust_min_n": list(RL_THRUST.min_n),
        "thrust_max_n": list(RL_THRUST.max_n),
        "dt_s": DT_S,
        "reward": {k: v for k, v in REWARD.__dict__.items()},
        "state_scale": STATE_SCALE.tolist(),
    }


def runs_to_demos(runs: list[disc.DiscreteRun]) -> DemoSet:
    parts = []
    for e, r in enumerate(runs):
        n = len(r.actions)
        dones = np.zeros(n, dtype=bool)
        if n and r.terminated:
            dones[-1] = True
        parts.append((r.states[:-1], r.actions, r.rewards, r.states[1:], dones, np.full(n, e)))
    cols = list(zip(*parts, strict=True))
    return DemoSet(
        np.concatenate(cols[0]).astype(np.float64),
        np.concatenate(cols[1]).astype(np.int64),
        np.concatenate(cols[2]).astype(np.float64),
        np.concatenate(cols[3]).astype(np.float64),
        np.concatenate(cols[4]).astype(bool),
        np.concatenate(cols[5]).astype(np.int64),
    )


def build_demos(
    initial_states: np.ndarray,
    n_per_axis: tuple[int, int, int] = N_ACTIONS_PER_AXIS,
    method: str = ocp.DEFAULT_METHOD,
    objective: str = "energy",
    progress: bool = True,
) -> tuple[DemoSet, dict[str, Any]]:
    """Solve the OCP from each initial state (K, 7), discretise (Eqs. 5-7), collect transitions.

    Failed solves are skipped (counted in stats); every discretised episode is kept, landed or
    not, as the paper does ("not an issue provided there are also successful episodes").
    """
    states = np.atleast_2d(np.asarray(initial_states, dtype=float))
    iterator: Any = states
    if progress:
        iterator = tqdm(states, desc="OCP solves", unit="case")
    results = [
        ocp.solve(s[0:3], s[3:6], s[6], method=method, objective=objective) for s in iterator
    ]
    good = [r for r in results if r.success]
    runs = disc.discretise_batch(good, n_per_axis) if good else []
    if not runs:
        raise ValueError("no OCP solve succeeded; nothing to build demonstrations from")
    demos = runs_to_demos(runs)
    stats = {
        "n_initial_states": int(len(states)),
        "n_solved": len(good),
        "n_episodes": len(runs),
        "n_landed": int(sum(r.landed for r in runs)),
        "n_transitions": int(len(demos.actions)),
        "method": method,
        "objective": objective,
    }
    return demos, stats


def save_demos(path: str | Path, demos: DemoSet, metadata: dict[str, Any]) -> None:
    """Write one compressed .npz with the arrays and a `metadata` JSON string."""
    meta = {**code_metadata(), **metadata}
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, **demos._asdict(), metadata=np.array(json.dumps(meta)))


def load_demos(
    path: str | Path, n_per_axis: tuple[int, int, int] = N_ACTIONS_PER_AXIS
) -> tuple[DemoSet, dict[str, Any]]:
    """(DemoSet, metadata); ValueError if the file is missing, corrupt, or made for other
    constants (n_per_axis, thrust limits, dt) than this code's."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"demo file {path} does not exist (make it with `pd-ocp demos`)")
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["metadata"]))
            demos = DemoSet(*(np.array(z[f]) for f in DemoSet._fields))
    except (OSError, KeyError, ValueError, zipfile.BadZipFile, json.JSONDecodeError) as exc:
        raise ValueError(f"demo file {path} is corrupt or not a demo file: {exc}") from exc
    want = code_metadata(n_per_axis)
    for key in ("n_per_axis", "thrust_min_n", "thrust_max_n", "dt_s"):
        if meta.get(key) != want[key]:
            raise ValueError(
                f"demo file {path} was made for {key}={meta.get(key)}, this code uses {want[key]}"
            )
    n = len(demos.actions)
    shapes_ok = (
        demos.states.shape == (n, 7)
        and demos.next_states.shape == (n, 7)
        and all(len(a) == n for a in (demos.rewards, demos.dones, demos.episode))
    )
    if not shapes_ok:
        raise ValueError(f"demo file {path} has inconsistent array shapes")
    return demos, meta
