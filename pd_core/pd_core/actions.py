"""Discrete action space: linearly spaced thrust levels per axis over the RL limits (Sec. 4.2).

Action index a = (i * n_j + j) * n_k + k (row-major over (n_i, n_j, n_k)); normalised level
l / (n - 1) maps to T_min + (T_max - T_min) l / (n - 1), the normalised action of Eq. 5.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pd_core.config import N_ACTIONS_PER_AXIS, RL_THRUST, ThrustLimits


@dataclass(frozen=True)
class ActionSpace:
    """Mapping between discrete action indices and thrust vectors (N)."""

    n_per_axis: tuple[int, int, int] = N_ACTIONS_PER_AXIS
    limits: ThrustLimits = RL_THRUST

    def __post_init__(self) -> None:
        if len(self.n_per_axis) != 3 or min(self.n_per_axis) < 2:
            raise ValueError(f"need at least 2 levels on each of 3 axes, got {self.n_per_axis}")
        grids = np.meshgrid(*[np.arange(n) for n in self.n_per_axis], indexing="ij")
        idx = np.stack([g.ravel() for g in grids], axis=-1)
        object.__setattr__(self, "_levels", idx)
        object.__setattr__(self, "_table", self.levels_to_thrust(idx))

    @property
    def n(self) -> int:
        return int(np.prod(self.n_per_axis))

    @property
    def table_n(self) -> np.ndarray:
        """Thrust (n, 3) in N of every action, indexed by action."""
        return self._table

    @property
    def level_table(self) -> np.ndarray:
        """Integer levels (n, 3) of every action."""
        return self._levels

    def levels_to_thrust(self, levels: np.ndarray) -> np.ndarray:
        frac = np.asarray(levels, dtype=float) / (np.asarray(self.n_per_axis) - 1.0)
        return self.limits.lo + frac * (self.limits.hi - self.limits.lo)

    def levels_to_action(self, levels: np.ndarray) -> np.ndarray:
        levels = np.asarray(levels)
        _, n_j, n_k = self.n_per_axis
        return (levels[..., 0] * n_j + levels[..., 1]) * n_k + levels[..., 2]

    def check(self, action: int | np.ndarray) -> np.ndarray:
        """Integer actions, or ValueError naming the bad ones."""
        a = np.asarray(action)
        if a.dtype.kind not in "iu" and not (a.dtype.kind == "f" and np.all(a == np.round(a))):
            raise ValueError(f"actions must be integers, got {a!r}")
        a = a.astype(np.int64)
        bad = (a < 0) | (a >= self.n)
        if np.any(bad):
            raise ValueError(f"action(s) {np.unique(a[bad]).tolist()} outside [0, {self.n})")
        return a

    def thrust(self, action: int | np.ndarray) -> np.ndarray:
        """Thrust (..., 3) in N of action index/indices; ValueError if out of range."""
        return self._table[self.check(action)]


DEFAULT_ACTIONS = ActionSpace()
