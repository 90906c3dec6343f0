"""The physical state vector, its scaling for the network (Eqs. 20-21) and its validation."""

from __future__ import annotations

import numpy as np

from pd_core.config import NEAR_PAD_SCALE, STATE_SCALE, THRUST_INPUT_SPAN

# Plausibility bounds for states coming from outside (nodes, files, users): far beyond anything
# the lander flies, tight enough to catch unit mix-ups and garbage.
MAX_ABS_POSITION_M = 1e6
MAX_ABS_VELOCITY_MPS = 1e4
MAX_MASS_KG = 1e6
STATE_LIMITS = np.array([MAX_ABS_POSITION_M, MAX_ABS_VELOCITY_MPS, MAX_MASS_KG])
"""the three bounds above, as the compiled check takes them (`pd_core.runtime.kernels`)"""


def scale_state(state: np.ndarray) -> np.ndarray:
    """Network input of Eq. 20: [x, v, m] * s_scale (Eq. 21), float32."""
    return (np.asarray(state, dtype=float) * STATE_SCALE).astype(np.float32)


def thrust_input(fraction: np.ndarray | float) -> np.ndarray:
    """The network's thrust input of a delivered vertical thrust fraction (..., dimensionless):
    (1 - fraction) / THRUST_INPUT_SPAN, float32; 0 for a nominal engine."""
    return ((1.0 - np.asarray(fraction, dtype=float)) / THRUST_INPUT_SPAN).astype(np.float32)


def scale_inputs(rows: np.ndarray) -> np.ndarray:
    """Network inputs of physical rows (..., 7) or (..., 8): Eq. 20's scaled state, then, for an
    8th column (the thrust fraction counted on, `thrust_input`), its thrust input; float32."""
    r = np.asarray(rows, dtype=float)
    if r.shape[-1] == 7:
        return scale_state(r)
    if r.shape[-1] != 8:
        raise ValueError(f"expected rows of 7 state values or 8 with a thrust fraction: {r.shape}")
    return np.concatenate([scale_state(r[..., :7]), thrust_input(r[..., 7:])], axis=-1)


# gains on the Eq. 21-scaled position and velocity that give tanh(state / NEAR_PAD_SCALE)
NEAR_PAD_GAIN = 1.0 / (NEAR_PAD_SCALE * STATE_SCALE[:6])
N_NEAR_PAD = len(NEAR_PAD_SCALE)


def near_pad_features(scaled: np.ndarray) -> np.ndarray:
    """(..., 6) tanh(position / 2, 2, 10 m; velocity / 0.5, 0.5, 2 m/s) from Eq. 21 inputs
    (..., 7): resolves the last metres, where Eq. 21's 0.01/m cannot, and saturates above."""
    return np.tanh(np.asarray(scaled)[..., :N_NEAR_PAD] * NEAR_PAD_GAIN)


def as_state_rows(states: np.ndarray) -> np.ndarray:
    """States (B, 7) as contiguous floats (values unchecked), or `check_state`'s ValueError on
    their shape."""
    s = np.asarray(states, dtype=float)
    if s.shape[-1:] != (7,):
        check_state(s)
    return np.ascontiguousarray(s.reshape(-1, 7))


def _one_state_ok(x: float, y: float, z: float, vx: float, vy: float, vz: float, m: float) -> bool:
    """True if one state passes every check of `check_state` (NaN and inf fail a comparison;
    no `max`, which would skip a NaN)."""
    p, v = MAX_ABS_POSITION_M, MAX_ABS_VELOCITY_MPS
    return (
        abs(x) <= p and abs(y) <= p and abs(z) <= p
        and abs(vx) <= v and abs(vy) <= v and abs(vz) <= v
        and 0.0 < m <= MAX_MASS_KG
    )  # fmt: skip


def check_state(state: np.ndarray) -> np.ndarray:
    """A float (..., 7) copy of `state`, or ValueError saying what is wrong with it."""
    s = np.asarray(state, dtype=float)
    if s.shape[-1:] != (7,):
        raise ValueError(f"state must have 7 entries [x, y, z, vx, vy, vz, m], got shape {s.shape}")
    if s.shape == (7,) and _one_state_ok(*s.tolist()):
        return s.copy()  # the common case, one good state, in plain floats (~10x faster)
    if not np.all(np.isfinite(s)):
        raise ValueError(f"state has NaN or infinite values: {s.tolist()}")
    if np.any(np.abs(s[..., 0:3]) > MAX_ABS_POSITION_M):
        raise ValueError(f"position beyond {MAX_ABS_POSITION_M:g} m: {s[..., 0:3].tolist()}")
    if np.any(np.abs(s[..., 3:6]) > MAX_ABS_VELOCITY_MPS):
        raise ValueError(f"velocity beyond {MAX_ABS_VELOCITY_MPS:g} m/s: {s[..., 3:6].tolist()}")
    if np.any(s[..., 6] <= 0.0) or np.any(s[..., 6] > MAX_MASS_KG):
        raise ValueError(f"mass must be in (0, {MAX_MASS_KG:g}] kg, got {s[..., 6].tolist()}")
    return s.copy()
