"""Optimal control problem of Eq. 4: open-loop thrust from an initial state to rest at the pad.

The public face: `solve(position, velocity, mass, **options) -> OCPResult` (never raises for a
bad request or a failed solve), `check_request`, and `Problem` with `solve_problem` for callers
that build the problem once and solve it many times (python-control's `OptimalControlProblem`
is the model). Inside:

* `model`: the transcription (`Problem`, `Grid`, the closed-form flight and its exact gradients);
* `request`: the names and bounds a request may use (`check_request`);
* `guess`: the constant-thrust initial guess of Sec. 3.1;
* `slsqp`: the paper's SciPy SLSQP (finite-difference or exact gradients);
* `qp`: the fast method for the energy objective (PDAS QP, root of dJ*/dt_f);
* `fuel`: the fast method for the fuel objective (LP passes, Brent on t_f, trust-region SLP).

* `solver`: `solve`, `solve_problem` and `OCPResult` over the three.

Both fast methods find local optima of the non-convex Eq. 4 (the mass couples the axes).

Names load on first use (PEP 562): `import pd_core.ocp` or `pd_core.ocp.request` loads no solver,
so the simulator and the runtime can check a request without SciPy or HiGHS.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from pd_core.config import OCP_THRUST
    from pd_core.ocp.guess import initial_guess
    from pd_core.ocp.model import EXHAUST_VELOCITY_MPS, Problem, fly
    from pd_core.ocp.request import (
        DEFAULT_METHOD,
        MAX_CONTROL_POINTS,
        METHODS,
        OBJECTIVES,
        check_request,
    )
    from pd_core.ocp.solver import ENERGY_COST_SCALE, OCPResult, solve, solve_problem

# public name -> the module that defines it, imported on first use
_HOME = {
    "DEFAULT_METHOD": "pd_core.ocp.request",
    "MAX_CONTROL_POINTS": "pd_core.ocp.request",
    "METHODS": "pd_core.ocp.request",
    "OBJECTIVES": "pd_core.ocp.request",
    "check_request": "pd_core.ocp.request",
    "EXHAUST_VELOCITY_MPS": "pd_core.ocp.model",
    "Problem": "pd_core.ocp.model",
    "fly": "pd_core.ocp.model",
    "initial_guess": "pd_core.ocp.guess",
    "OCP_THRUST": "pd_core.config",
    "ENERGY_COST_SCALE": "pd_core.ocp.solver",
    "OCPResult": "pd_core.ocp.solver",
    "solve": "pd_core.ocp.solver",
    "solve_problem": "pd_core.ocp.solver",
}


def __getattr__(name: str) -> Any:
    if name not in _HOME:
        raise AttributeError(f"module 'pd_core.ocp' has no attribute {name!r}")
    value = getattr(importlib.import_module(_HOME[name]), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_HOME))


__all__ = [
    "DEFAULT_METHOD",
    "ENERGY_COST_SCALE",
    "EXHAUST_VELOCITY_MPS",
    "MAX_CONTROL_POINTS",
    "METHODS",
    "OBJECTIVES",
    "OCPResult",
    "OCP_THRUST",
    "Problem",
    "check_request",
    "fly",
    "initial_guess",
    "solve",
    "solve_problem",
]
