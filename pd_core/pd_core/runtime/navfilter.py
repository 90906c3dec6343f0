"""Navigation filter: guidance acts on a state estimated from noisy navigation (ours).

Each axis carries a Kalman filter on [position, velocity, unmodelled acceleration]:
- the prediction flies the command the plant applied over the last step (the lag and thrust
  matrix `pd_core.runtime.latency` identifies) on the nominal dynamics;
- the unmodelled acceleration is a random walk (thrust error, misalignment, mass error, steady
  wind); gusts are white acceleration noise on top;
- the measurement noise is not told: it is estimated from the second differences of the
  measurements less what the known accelerations explain (`NavFilter._learn_noise`), floored at
  the config's position and velocity floors.

The estimate replaces the observation only where the estimated noise exceeds a floor, after
`warm_steps` of evidence: without navigation noise the guidance flies the observed state to the
bit. The mass passes through as observed. Settings: `pd_core.runtime.config.NavFilterConfig`.
"""

from __future__ import annotations

import numpy as np

from pd_core.config import DT_S
from pd_core.runtime.config import NavFilterConfig
from pd_core.runtime.rowmemory import RowMemory


def transition(dt_s: float = DT_S) -> tuple[np.ndarray, np.ndarray]:
    """(F, B) of one axis' [position, velocity, acceleration] over a step of dt_s."""
    f = np.array([[1.0, dt_s, 0.5 * dt_s**2], [0.0, 1.0, dt_s], [0.0, 0.0, 1.0]])
    return f, np.array([0.5 * dt_s**2, dt_s, 0.0])


def kalman_step(
    x: np.ndarray,
    cov: np.ndarray,
    accel_mps2: np.ndarray,
    z: np.ndarray,
    noise_var: np.ndarray,
    q: np.ndarray,
    dt_s: float = DT_S,
) -> tuple[np.ndarray, np.ndarray]:
    """One predict + update per lander and axis: the estimate x (B, 3, 3) [axis, (position m,
    velocity m/s, unmodelled acceleration m/s^2)] and its covariance cov (B, 3, 3, 3), the known
    acceleration applied over the step (B, 3), m/s^2, the measured [position, velocity] (B, 3, 2)
    and the measurement noise variances (B, 2); q (3, 3) the process noise of a step. Returns
    the updated estimate and covariance."""
    f, b = transition(dt_s)
    xm = np.einsum("ij,baj->bai", f, x) + accel_mps2[:, :, None] * b
    pm = np.einsum("ij,bajk,lk->bail", f, cov, f) + q
    nu = z - xm[:, :, 0:2]
    s = pm[:, :, 0:2, 0:2] + noise_var[:, None, None, :] * np.eye(2)
    gain = np.einsum("baij,bajk->baik", pm[:, :, :, 0:2], np.linalg.inv(s))
    x_new = xm + np.einsum("baij,baj->bai", gain, nu)
    cov_new = pm - np.einsum("baij,bajk->baik", gain, pm[:, :, 0:2, :])
    return x_new, cov_new


class NavFilter(RowMemory):
    """Per-row (one lander each) filter memory; see the module docstring."""

    def __init__(self, cfg: NavFilterConfig, n_rows: int = 1) -> None:
        self.cfg = cfg
        _, b = transition()
        self._q = cfg.unmodelled_accel_mps2**2 * np.outer(b, b) + np.diag(
            [0.0, 0.0, cfg.bias_walk_mps2**2]
        )
        self._p0 = np.diag(np.square([cfg.initial_sd_m, cfg.initial_sd_mps, cfg.initial_sd_mps2]))
        self._floor = np.array([cfg.position_floor_m**2, cfg.velocity_floor_mps**2])
        self._prior = np.square([cfg.prior_noise_m, cfg.prior_noise_mps])
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

    def estimate(
        self, observed: np.ndarray, rows: np.ndarray, accel_mps2: np.ndarray
    ) -> np.ndarray:
        """States (B, 7) to fly for the observed states (B, 7) of rows (B,), given the
        acceleration (B, 3), m/s^2, the commands applied over the last step gave (thrust / m + g;
        unused for a row's first observation)."""
        out = np.array(observed, dtype=float).reshape(-1, 7)
        z = np.stack([out[:, 0:3], out[:, 3:6]], axis=-1)
        first = np.isnan(self._x[rows, 0, 0])
        if first.any():
            r = rows[first]
            self._x[r] = np.concatenate([z[first], np.zeros((len(r), 3, 1))], axis=-1)
            self._cov[r] = self._p0
            self._z1[r] = z[first]
        if first.all():
            return out
        old = ~first
        r, z, a = rows[old], z[old], accel_mps2[old]
        steps = self._steps[r] + 1
        self._steps[r] = steps
        self._learn_noise(r, z, a, steps)
        # until enough evidence, the noise is taken as the largest designed for
        warm = (steps < self.cfg.warm_steps)[:, None]
        assumed = np.where(warm, self._prior, np.maximum(self.noise_var[r], self._floor))
        x, cov = kalman_step(self._x[r], self._cov[r], a, z, assumed, self._q)
        self._x[r], self._cov[r] = x, cov
        on = ~warm[:, 0] & (self.noise_var[r] > self._floor).any(axis=1)
        self.engaged[r] = on
        sub = out[old]
        sub[on, 0:3] = x[on, :, 0]
        sub[on, 3:6] = x[on, :, 1]
        out[old] = sub
        return out

    def _learn_noise(self, r: np.ndarray, z: np.ndarray, a: np.ndarray, steps: np.ndarray) -> None:
        """Second differences of the measurements, less what the known accelerations explain,
        are the noise alone (6 sigma^2 of white noise; a steady unmodelled acceleration cancels
        in the velocity's and moves the position's by b dt^2, centimetres): an estimate that does
        not depend on how well the filter itself is tuned."""
        z1, z2, a1 = self._z1[r], self._z2[r], self._a1[r]
        self._z2[r], self._z1[r], self._a1[r] = z1, z, a
        has = steps >= 2
        if not has.any():
            return
        d2 = (z - 2.0 * z1 + z2)[has]
        d2[..., 0] -= 0.5 * (a + a1)[has] * DT_S**2
        d2[..., 1] -= (a - a1)[has] * DT_S
        rh = r[has]
        n = steps[has] - 1
        forget = self.cfg.forget_per_step
        self._d2_sq[rh] = forget * self._d2_sq[rh] + (1.0 - forget) * (d2**2).mean(axis=1)
        self.noise_var[rh] = self._d2_sq[rh] / (6.0 * (1.0 - forget**n))[:, None]
