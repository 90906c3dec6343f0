"""Initial guess of Sec. 3.1: constant thrust, Eq. 19 for the horizontal axes, grid search."""

from __future__ import annotations

import numpy as np

from pd_core.config import GRAVITY_MPS2, OCP_THRUST, ThrustLimits
from pd_core.ocp.model import EXHAUST_VELOCITY_MPS


def constant_thrust_flight(
    x0: np.ndarray, v0: np.ndarray, m0: float, thrust: np.ndarray, t: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form (x(t) m, v(t) m/s) under constant thrust (..., 3) N with the rocket equation."""
    mdot = np.abs(thrust).sum(axis=-1) / EXHAUST_VELOCITY_MPS
    a = mdot / m0
    at = np.minimum(a * t, 0.999)
    small = a * t < 1e-6
    a_safe = np.where(small, 1.0, a)
    # int_0^t 1/(m0 - mdot s) ds and its double integral, with the zero-flow limits.
    i1 = np.where(small, t / m0, -np.log1p(-at) / (a_safe * m0))
    i2 = np.where(small, 0.5 * t * t / m0, ((1 - at) * np.log1p(-at) + at) / (a_safe**2 * m0))
    v = v0 + GRAVITY_MPS2 * t[..., None] + thrust * i1[..., None]
    x = x0 + v0 * t[..., None] + 0.5 * GRAVITY_MPS2 * t[..., None] ** 2 + thrust * i2[..., None]
    return x, v


def initial_guess(
    x0: np.ndarray,
    v0: np.ndarray,
    m0: float,
    limits: ThrustLimits = OCP_THRUST,
    t_grid_s: np.ndarray | None = None,
    n_t3: int = 49,
) -> tuple[np.ndarray, float]:
    """(constant thrust (3,) N, t_f s) of Sec. 3.1: Eq. 19 for T1, T2, grid search for t_f, T3.

    Picks the pair minimising |[x_f, v_f]| among those whose altitude never goes below 0.
    """
    t_grid = np.arange(10.0, 150.01, 1.0) if t_grid_s is None else np.asarray(t_grid_s)
    n_alt = 41 if t_grid_s is None else 17
    t3 = np.linspace(limits.lo[2], limits.hi[2], n_t3)
    tf, t3g = np.meshgrid(t_grid, t3, indexing="ij")
    thr = np.empty(tf.shape + (3,))
    for a in range(2):
        thr[..., a] = np.clip(-2 * m0 * (x0[a] + v0[a] * tf) / tf**2, limits.lo[a], limits.hi[a])
    thr[..., 2] = t3g
    xf, vf = constant_thrust_flight(x0, v0, m0, thr, tf)
    frac = np.linspace(0.0, 1.0, n_alt)
    xs, _ = constant_thrust_flight(x0, v0, m0, thr[..., None, :], tf[..., None] * frac)
    ok = xs[..., 2].min(axis=-1) >= 0.0
    err = np.sqrt((xf**2).sum(-1) + (vf**2).sum(-1))
    err = np.where(ok, err, np.inf)
    if not np.isfinite(err).any():
        err = np.sqrt((xf**2).sum(-1) + (vf**2).sum(-1))
    i = np.unravel_index(np.argmin(err), err.shape)
    return thr[i], float(tf[i])
