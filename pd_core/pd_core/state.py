"""The physical state vector, its scaling for the network (Eqs. 20-21) and its validation."""

from __future__ import annotations

import numpy as np

from pd_core.config import STATE_SCALE

# Plausibility bounds for states coming from outside (nodes, files, users): far beyond anything
# the lander flies, tight enough to catch unit mix-ups and garbage.
MAX_ABS_POSITION_M = 1e6
MAX_ABS_VELOCITY_MPS = 1e4
MAX_MASS_KG = 1e6


def scale_state(state: np.ndarray) -> np.ndarray:
    """Network input of Eq. 20: [x, v, m] * s_scale (Eq. 21), float32."""
    return (np.asarray(state, dtype=float) * STATE_SCALE).astype(np.float32)


def check_state(state: np.ndarray) -> np.ndarray:
    """A float (..., 7) copy of `state`, or ValueError saying what is wrong with it."""
    s = np.asarray(state, dtype=float)
    if s.shape[-1:] != (7,):
        raise ValueError(f"state must have 7 entries [x, y, z, vx, vy, vz, m], got shape {s.shape}")
    if not np.all(np.isfinite(s)):
        raise ValueError(f"state has NaN or infinite values: {s.tolist()}")
    if np.any(np.abs(s[..., 0:3]) > MAX_ABS_POSITION_M):
        raise ValueError(f"position beyond {MAX_ABS_POSITION_M:g} m: {s[..., 0:3].tolist()}")
    if np.any(np.abs(s[..., 3:6]) > MAX_ABS_VELOCITY_MPS):
        raise ValueError(f"velocity beyond {MAX_ABS_VELOCITY_MPS:g} m/s: {s[..., 3:6].tolist()}")
    if np.any(s[..., 6] <= 0.0) or np.any(s[..., 6] > MAX_MASS_KG):
        raise ValueError(f"mass must be in (0, {MAX_MASS_KG:g}] kg, got {s[..., 6].tolist()}")
    return s.copy()
