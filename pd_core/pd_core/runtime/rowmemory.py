"""Memory with one row per lander, for runtime stages that fly many landers at once (ours)."""

from __future__ import annotations

import numpy as np


class RowMemory:
    """Arrays whose first axis is the lander (row), made by `_fresh`: a batch of episodes
    (`pd_core.episodes.fly_episodes`) and the policy node (row 0) share one
    implementation. `n_rows` is the number of rows held."""

    n_rows: int = 0

    def _fresh(self, n_rows: int) -> dict[str, np.ndarray]:
        """The memory of n_rows landers that have flown nothing yet (attribute name -> array)."""
        raise NotImplementedError

    def reset(self, n_rows: int) -> None:
        """Forget every lander: n_rows new ones."""
        for name, value in self._fresh(n_rows).items():
            setattr(self, name, value)
        self.n_rows = n_rows

    def grow(self, n_rows: int) -> None:
        """Room for n_rows landers; the rows kept so far keep their memory."""
        if n_rows <= self.n_rows:
            return
        for name, value in self._fresh(n_rows).items():
            old = getattr(self, name)
            value[: len(old)] = old
            setattr(self, name, value)
        self.n_rows = n_rows

    def clear(self, rows: np.ndarray) -> None:
        """Rows that start new episodes."""
        for name, value in self._fresh(len(rows)).items():
            getattr(self, name)[rows] = value
