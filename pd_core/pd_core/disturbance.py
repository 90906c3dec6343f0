"""Environmental disturbance force F_env of Eq. 2 (Sec. 3.2).

Gaussian per axis (mean 0 N, sigma 100 N), one sample per second, linearly interpolated between
samples. The samples ("knots") for a whole episode are drawn at reset from the episode's numpy
Generator, so an episode is reproducible from its seed and stepping needs no random numbers.
"""

from __future__ import annotations

import math

import numpy as np

from pd_core.config import DISTURBANCE, DisturbanceConfig


def n_knots(duration_s: float, cfg: DisturbanceConfig = DISTURBANCE) -> int:
    """Knots needed to interpolate over [0, duration_s] (both ends included)."""
    return math.ceil(duration_s / cfg.knot_interval_s) + 2


def sample_knots(
    rng: np.random.Generator, duration_s: float, cfg: DisturbanceConfig = DISTURBANCE
) -> np.ndarray:
    """Force samples (n_knots, 3) in N at t = 0, 1, 2, ... s."""
    return rng.normal(cfg.mean_n, cfg.sigma_n, size=(n_knots(duration_s, cfg), 3))


def force_at(
    knots_n: np.ndarray, t_s: np.ndarray | float, cfg: DisturbanceConfig = DISTURBANCE
) -> np.ndarray:
    """Linearly interpolated force (..., 3) at times t_s (...,); knots_n (..., n_knots, 3).

    Times past the last knot hold the last knot's value.
    """
    t = np.asarray(t_s, dtype=float) / cfg.knot_interval_s
    last = knots_n.shape[-2] - 1
    i0 = np.clip(np.floor(t).astype(np.intp), 0, last - 1)
    frac = np.clip(t - i0, 0.0, 1.0)[..., None]
    if knots_n.ndim == 3 and i0.ndim == 1:  # the vector env's case: one time per lander
        rows = np.arange(knots_n.shape[0])
        f0, f1 = knots_n[rows, i0], knots_n[rows, i0 + 1]
    else:
        f0 = np.take_along_axis(knots_n, i0[..., None, None], axis=-2)[..., 0, :]
        f1 = np.take_along_axis(knots_n, (i0 + 1)[..., None, None], axis=-2)[..., 0, :]
    return f0 + frac * (f1 - f0)
