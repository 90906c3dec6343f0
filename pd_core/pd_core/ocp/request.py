"""What an OCP request may ask: the names and bounds every entry point checks once, here.

`check_request` is the one gate: `Problem` runs it when it is built, `solve()` and the OCP node
call it before any work, so a bad request is refused in microseconds with one line saying why.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pd_core.config import DRY_MASS_KG
from pd_core.state import check_state

METHODS = ("qp", "slsqp")
OBJECTIVES = ("energy", "fuel")
DEFAULT_METHOD = "qp"
# ours: requests outside these are refused as absurd for this lander (state.check_state's bounds
# catch garbage; these catch requests the 11-12 kN lander cannot mean).
OCP_MAX_ABS_POSITION_M = 1e5
OCP_MAX_SPEED_MPS = 2e3
# ours: control points per axis. 2 is a straight line; 500 is one point per 0.2 s step of a
# 100 s flight (the Table 1/3 optima fly 40-90 s), beyond which points add no freedom, only
# time and memory (100000 points once took 20 s and 747 MB to fail).
MIN_CONTROL_POINTS = 2
MAX_CONTROL_POINTS = 500
# ours: a solve takes >= 10 ms (the fast method on an idle core), so a shorter budget can only
# time out; an hour is beyond any solve of this problem (the paper's SLSQP takes ~10 s).
MIN_TIMEOUT_S = 0.01
MAX_TIMEOUT_S = 3600.0


def _check_state(position: Any, velocity: Any, mass: Any) -> str | None:
    try:
        pos = np.asarray(position, dtype=float).reshape(-1)
        vel = np.asarray(velocity, dtype=float).reshape(-1)
        m = np.asarray(mass, dtype=float).reshape(-1)
    except (TypeError, ValueError) as exc:
        return f"position, velocity and mass must be numbers: {exc}"
    if pos.shape != (3,) or vel.shape != (3,) or m.shape != (1,):
        return (
            f"need 3 position, 3 velocity and 1 mass values, got {pos.size}, {vel.size}, {m.size}"
        )
    try:
        check_state(np.concatenate([pos, vel, m]))
    except ValueError as exc:
        return str(exc)
    # plain floats from here (all finite): a re-plan's `Problem.at` runs this every step
    (x, y, z), (vx, vy, vz), (mass,) = pos.tolist(), vel.tolist(), m.tolist()
    if z <= 0.0:
        return f"altitude must be > 0 m, got {z:g} m"
    if mass <= DRY_MASS_KG:
        return f"mass must exceed the dry mass {DRY_MASS_KG:g} kg, got {mass:g} kg"
    if max(abs(x), abs(y), abs(z)) > OCP_MAX_ABS_POSITION_M:
        return f"position beyond {OCP_MAX_ABS_POSITION_M:g} m is absurd for this lander"
    if math.sqrt(vx * vx + vy * vy + vz * vz) > OCP_MAX_SPEED_MPS:
        return f"speed beyond {OCP_MAX_SPEED_MPS:g} m/s is absurd for this lander"
    return None


def check_settings(
    method: Any = None, objective: Any = None, n_control: Any = None, timeout_s: Any = None
) -> str | None:
    """None if the solver settings given (None = not given) are allowed, else why not."""
    if method is not None and method not in METHODS:
        return f"unknown method {method!r}; choose one of {', '.join(METHODS)}"
    if objective is not None and objective not in OBJECTIVES:
        return f"unknown objective {objective!r}; choose one of {', '.join(OBJECTIVES)}"
    if n_control is not None and (
        isinstance(n_control, bool)
        or not isinstance(n_control, (int, np.integer))
        or not MIN_CONTROL_POINTS <= n_control <= MAX_CONTROL_POINTS
    ):
        return (
            f"n_control (control points) must be an integer in [{MIN_CONTROL_POINTS}, "
            f"{MAX_CONTROL_POINTS}], got {n_control!r}"
        )
    if timeout_s is not None:
        ok = isinstance(timeout_s, (int, float, np.floating, np.integer)) and math.isfinite(
            float(timeout_s)
        )
        if not ok or not MIN_TIMEOUT_S <= float(timeout_s) <= MAX_TIMEOUT_S:
            return (
                f"timeout_s must be in [{MIN_TIMEOUT_S:g}, {MAX_TIMEOUT_S:g}] s, got {timeout_s!r}"
            )
    return None


def check_request(
    position: Any,
    velocity: Any,
    mass: Any,
    *,
    method: Any = None,
    objective: Any = None,
    n_control: Any = None,
    timeout_s: Any = None,
) -> str | None:
    """None if (position m, velocity m/s, mass kg) and the settings given are a request the OCP
    can take, else one line saying why not. Settings left None are not checked."""
    return _check_state(position, velocity, mass) or check_settings(
        method, objective, n_control, timeout_s
    )
