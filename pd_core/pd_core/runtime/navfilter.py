"""Navigation filter: guidance acts on a state estimated from noisy navigation (ours).

Each axis carries a Kalman filter on [position, velocity, unmodelled acceleration]:
- the prediction flies the command the plant applied over the last step (the lag and thrust
  matrix `pd_core.runtime.latency` identifies) on the nominal dynamics;
- the unmodelled acceleration is a random walk (thrust error, misalignment, mass error, steady
  wind); gusts are white acceleration noise on top;
- the measurement noise is not told: it is estimated from the second differences of the
  measurements less what the known accelerations explain (`NavFilter.estimate`), floored at
  the config's position and velocity floors.

The estimate replaces the observation only where the estimated noise exceeds a floor, after
`warm_steps` of evidence: without navigation noise the guidance flies the observed state to the
bit. The mass passes through as observed. Settings: `pd_core.runtime.config.NavFilterConfig`.
The arithmetic, row by row, is compiled: `pd_core.runtime.kernels_nav` (`_nav_row`, on a
`NavMemory` and a `NavModel`).
"""

from __future__ import annotations

import numpy as np

from pd_core.config import DT_S
from pd_core.runtime.config import NavFilterConfig
from pd_core.runtime.kernels import consts
from pd_core.runtime.kernels_nav import nav_estimate_rows
from pd_core.runtime.kernels_state import NavMemory, NavModel
from pd_core.runtime.rowmemory import RowMemory


def transition(dt_s: float = DT_S) -> tuple[np.ndarray, np.ndarray]:
    """(F, B) of one axis' [position, velocity, acceleration] over a step of dt_s."""
    f = np.array([[1.0, dt_s, 0.5 * dt_s**2], [0.0, 1.0, dt_s], [0.0, 0.0, 1.0]])
    return f, np.array([0.5 * dt_s**2, dt_s, 0.0])


class NavFilter(RowMemory):
    """Per-row (one lander each) filter memory; see the module docstring."""

    def __init__(self, cfg: NavFilterConfig, n_rows: int = 1) -> None:
        self.cfg = cfg
        self._f, b = transition()
        self._b = b
        self._q = cfg.unmodelled_accel_mps2**2 * np.outer(b, b) + np.diag(
            [0.0, 0.0, cfg.bias_walk_mps2**2]
        )
        self._p0 = np.diag(np.square([cfg.initial_sd_m, cfg.initial_sd_mps, cfg.initial_sd_mps2]))
        self._floor = np.array([cfg.position_floor_m**2, cfg.velocity_floor_mps**2])
        self._prior = np.square([cfg.prior_noise_m, cfg.prior_noise_mps])
        params = np.array(
            [cfg.warm_steps, cfg.forget_per_step, *self._floor, *self._prior], dtype=float
        )
        self.model = NavModel(
            params=params, f=self._f, bvec=self._b, q=self._q, p0=self._p0, dynamics=consts()
        )
        """the settings the kernels take (`NavModel`)"""
        self.reset(n_rows)

    def _fresh(self, n_rows: int) -> dict[str, np.ndarray]:
        return {
            "_x": np.full((n_rows, 3, 3), np.nan),  # nan: no observation yet
            "_cov": np.tile(self._p0, (n_rows, 3, 1, 1)),
            "_z1": np.zeros((n_rows, 3, 2)),  # last [position, velocity] measured
            "_z2": np.zeros((n_rows, 3, 2)),  # ... and the one before
            "_a1": np.zeros((n_rows, 3)),  # known acceleration of the step before last
            "_d2_sq": np.zeros((n_rows, 2)),  # running mean square of the second differences
            "_steps": np.zeros(n_rows, dtype=np.int64),
            # the measurement noise variances (position m^2, velocity (m/s)^2) each row sees
            "noise_var": np.zeros((n_rows, 2)),
            # rows flying the estimate (else the observation)
            "engaged": np.zeros(n_rows, dtype=bool),
        }

    def steps(self, rows: np.ndarray) -> np.ndarray:
        """(B,) observations of rows (B,) the noise estimate has learnt from."""
        return self._steps[np.asarray(rows, dtype=np.int64)]

    def memory(self) -> NavMemory:
        """The memory the kernels take (`NavMemory`): the arrays themselves, until `reset` or
        `grow` replace them."""
        return NavMemory(
            x=self._x, cov=self._cov, z1=self._z1, z2=self._z2, a1=self._a1, d2_sq=self._d2_sq,
            steps=self._steps, noise_var=self.noise_var, engaged=self.engaged,
        )  # fmt: skip

    def estimate(
        self, observed: np.ndarray, rows: np.ndarray, accel_mps2: np.ndarray
    ) -> np.ndarray:
        """States (B, 7) to fly for the observed states (B, 7) of rows (B,), given the
        acceleration (B, 3), m/s^2, the commands applied over the last step gave (thrust / m + g;
        unused for a row's first observation).

        A row's first observation starts its filter. After that, each step: the second
        differences of the measurements, less what the known accelerations explain, are the
        noise alone (6 sigma^2 of white noise; a steady unmodelled acceleration cancels in the
        velocity's and moves the position's by b dt^2, centimetres): an estimate that does not
        depend on how well the filter itself is tuned; until `warm_steps` of evidence the noise
        is taken as the largest designed for (the priors), then as estimated, floored; one
        Kalman predict + update per axis."""
        rows = np.asarray(rows, dtype=np.int64)
        obs = np.ascontiguousarray(observed, dtype=float).reshape(-1, 7)
        acc = np.ascontiguousarray(accel_mps2, dtype=float).reshape(-1, 3)
        self.grow(int(rows.max()) + 1 if len(rows) else 0)
        out = np.empty_like(obs)
        nav_estimate_rows(rows, obs, acc, out, self.memory(), self.model)
        return out
