"""The runtime layer's per-lander arithmetic, compiled (numba): one loop over the rows given.

`pd_core.runtime.latency`, `pd_core.runtime.navfilter` and `pd_core.runtime.rules` keep their
memory and settings in numpy arrays (one row per lander, `RowMemory`) and call these kernels on
them; each kernel does, row by row, the arithmetic those modules document (lag residuals and
scores, the thrust-matrix Kalman step, the window sums, the navigation filter's noise learning and
Kalman step with a closed-form 2x2 inverse, the propagation on the nominal dynamics of
`pd_core.dynamics.step`, the vertical thrust scale, the three rules), in the order of operations
of the numpy it replaced (three-term dot products as numpy's einsum sums them, `_dot3`): the
shipped files fly the same actions to the bit on the `standard` campaign. The handover condition
repeats, for one lander, `braking_accel_mps2` and `lateral_brake_accel_mps2` of
`pd_core.teachers.zemzev`. One decision of one lander costs microseconds instead of ~400 small
numpy calls.

Settings arrive as arrays of floats (`consts()`, and each module's own) and scalars, in named
tuples with the memory they act on (`pd_core.runtime.kernels_state`): nothing from a config is
frozen into the compiled code. `cache=True` keeps the machine code next to this file: a fresh
process imports numba (0.4 s) and loads the kernels (0.15 s; `pd_core.runtime.layer` does, when
the first `Runtime` is built); after an edit of this file the first process compiles them again
(about 10 s).

Numba comes from `pd_core.jit` (imported without SciPy on the flight path). The braking law is
`pd_core.envelope`'s, compiled into `kernels_rules`; numba's cache does not see an edit of it, so
the cache index of these modules is dropped here where any of their sources is newer
(`pd_core.jit.drop_stale_cache`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pd_core import envelope
from pd_core.config import DRY_MASS_KG, DT_S, G0_MPS2, GRAVITY_MPS2, ISP_S
from pd_core.dynamics import PHI1, PHI2
from pd_core.jit import drop_stale_cache, njit

_HERE = Path(__file__).resolve().parent
_KERNELS = sorted(_HERE.glob("kernels*.py"))
drop_stale_cache(_KERNELS, [*_KERNELS, Path(envelope.__file__)])


def consts() -> np.ndarray:
    """[dt s, g (3) m/s^2, dry mass kg, Isp g0 m/s, dt^2, PHI1 (9), PHI2 (9)]: the nominal
    dynamics the kernels fly (`pd_core.dynamics.step`)."""
    head = [DT_S, *GRAVITY_MPS2, DRY_MASS_KG, ISP_S * G0_MPS2, DT_S**2]
    return np.array(head + list(PHI1) + list(PHI2), dtype=float)


# indices into consts()
_DT, _G, _DRY, _ISPG0, _DT2, _PHI1, _PHI2 = 0, 1, 4, 5, 6, 7, 16
N_PHI = len(PHI1)


@njit(cache=True)
def states_valid(s: np.ndarray, limits: np.ndarray) -> bool:
    """True where every state (B, 7) passes `pd_core.state.check_state` (finite, positions and
    velocities within limits[0], limits[1], mass in (0, limits[2]]); the caller lets
    `check_state` say what is wrong otherwise."""
    for b in range(s.shape[0]):
        for i in range(7):
            v = s[b, i]
            lim = limits[0] if i < 3 else (limits[1] if i < 6 else limits[2])
            if not abs(v) <= lim:  # also NaN
                return False
        if not s[b, 6] > 0.0:
            return False
    return True


@njit(cache=True)
def _horner(c: np.ndarray, start: int, z: float) -> float:
    out = c[start]
    for k in range(start + 1, start + N_PHI):
        out *= z
        out += c[k]
    return out


@njit(cache=True)
def step_nominal(s: np.ndarray, thrust: np.ndarray, c: np.ndarray) -> None:
    """`pd_core.dynamics.step` of one state (7,) in place under thrust (3,) N, no disturbance."""
    dt = c[_DT]
    m0 = s[6]
    burn = (abs(thrust[0]) + abs(thrust[1]) + abs(thrust[2])) / c[_ISPG0] * dt
    fuel_left = max(m0 - c[_DRY], 0.0)
    scale = 1.0
    if burn > fuel_left:
        scale = fuel_left / burn if burn > 0.0 else 1.0
        burn = burn * scale
    z = burn / m0
    h1 = _horner(c, _PHI1, z)
    h2 = _horner(c, _PHI2, z)
    dt_m = dt / m0
    for i in range(3):
        a = (thrust[i] * scale + 0.0) * dt_m
        gdt = c[_G + i] * dt
        v0 = s[3 + i]
        s[i] = s[i] + dt * (v0 + 0.5 * gdt + a * h2)
        s[3 + i] = v0 + gdt + a * h1
    s[6] = m0 - burn


@njit(cache=True)
def _dot3(a0: float, a1: float, a2: float, b0: float, b1: float, b2: float) -> float:
    """a . b summed as numpy's einsum sums three products: (0 + 2) + 1."""
    return (a0 * b0 + a2 * b2) + a1 * b1


@njit(cache=True)
def _matvec(m: np.ndarray, u: np.ndarray, out: np.ndarray) -> None:
    for i in range(3):
        out[i] = _dot3(m[i, 0], m[i, 1], m[i, 2], u[0], u[1], u[2])
