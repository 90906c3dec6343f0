"""The OCP's entry points: `solve` (from a request) and `solve_problem` (a built `Problem`),
both returning an `OCPResult` and never raising for a bad request or a failed solve.

Importing this module loads every solver (SciPy's SLSQP, LAPACK, HiGHS); `pd_core.ocp` imports it
only when one of these names is used.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pd_core.config import OCP_CONTROL_POINTS, OCP_THRUST, ThrustLimits
from pd_core.ocp.fuel import solve_fuel
from pd_core.ocp.model import (
    Grid,
    Problem,
    SolverOutput,
    control_times,
)
from pd_core.ocp.qp import solve_energy
from pd_core.ocp.request import (
    DEFAULT_METHOD,
    check_request,
    check_settings,
)
from pd_core.ocp.slsqp import solve_slsqp

ENERGY_COST_SCALE = 1e-6  # reported energy cost in kN^2 s
# ours: a result counts as converged when the re-flown final state is this close to rest at 0.
SUCCESS_POSITION_M = 0.3
SUCCESS_VELOCITY_MPS = 0.02
_OPTIONS = {
    "slsqp": {"exact_gradients", "maxiter", "ftol"},
    "qp": {"passes", "final_passes", "tf_tol_s"},
}


@dataclass
class OCPResult:
    """Outcome of `solve`. `success` is False (never an exception) for a failed or refused solve."""

    success: bool
    message: str
    time_of_flight: float = math.nan  # s
    fuel: float = math.nan  # kg
    cost: float = math.nan  # kN^2 s ("energy") or kg ("fuel")
    thrust: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (n_control, 3) N
    control_times: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (n_control,) s
    states: np.ndarray = field(default_factory=lambda: np.zeros((0, 7)))  # (n_steps + 1, 7)
    state_times: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (n_steps + 1,) s
    solve_time: float = 0.0  # s, wall clock
    method: str = ""
    objective: str = ""
    iterations: int = 0  # SLSQP iterations, or t_f evaluations of "qp"

    @property
    def final_position(self) -> np.ndarray:
        return self.states[-1, 0:3].copy() if len(self.states) else np.full(3, np.nan)

    @property
    def final_velocity(self) -> np.ndarray:
        return self.states[-1, 3:6].copy() if len(self.states) else np.full(3, np.nan)

    @property
    def step_thrust(self) -> np.ndarray:
        """Thrust (n_steps, 3) N held over each integration step (midpoint interpolation)."""
        if not len(self.thrust):
            return np.zeros((0, 3))
        return Grid.make(self.time_of_flight, len(self.thrust)).interp(self.thrust)


def result_of(pb: Problem, out: SolverOutput, method: str, t_start: float) -> OCPResult:
    """`OCPResult` of a solver's output: re-flown states, cost, and whether rest was reached."""
    p, t_f = out.p, out.t_f
    states, times = pb.simulate(p, t_f)
    g = pb.grid(t_f)
    cost = pb.cost(pb.fly(p, g), g)
    cost = cost * ENERGY_COST_SCALE if pb.objective == "energy" else cost
    pos_err = float(np.linalg.norm(states[-1, 0:3]))
    vel_err = float(np.linalg.norm(states[-1, 3:6]))
    reached = pos_err <= SUCCESS_POSITION_M and vel_err <= SUCCESS_VELOCITY_MPS
    msg = out.message
    if out.ok and not reached:
        msg = (
            f"{msg}; final state misses rest at the pad: |x_f| {pos_err:.3g} m, "
            f"|v_f| {vel_err:.3g} m/s"
        )
    if not np.all(np.isfinite(states)):
        reached = False
        msg = f"{msg}; non-finite states"
    return OCPResult(
        success=bool(out.ok and reached),
        message=msg,
        time_of_flight=t_f,
        fuel=float(pb.m0 - states[-1, 6]),
        cost=float(cost),
        thrust=p,
        control_times=control_times(t_f, pb.n_control),
        states=states,
        state_times=times,
        solve_time=time.perf_counter() - t_start,
        method=method,
        objective=pb.objective,
        iterations=out.iterations,
    )


def solve_problem(
    pb: Problem,
    *,
    method: str = DEFAULT_METHOD,
    timeout_s: float | None = None,
    **options: Any,
) -> OCPResult:
    """Solve a built `Problem` (free final time). Never raises for bad settings or a failed
    solve: `success` is False and `message` says why. Options as `solve`."""
    t_start = time.perf_counter()
    why = check_settings(method=method, timeout_s=timeout_s)
    deadline = math.inf if timeout_s is None or why else t_start + float(timeout_s)
    return _solve_built(pb, str(method), deadline, t_start, why, options)


def _solve_built(
    pb: Problem, method: str, deadline: float, t_start: float, why: str | None, options: dict
) -> OCPResult:
    base = {"method": method, "objective": pb.objective}
    if why is None and set(options) - _OPTIONS[method]:
        why = f"unknown option(s) for {method}: {sorted(set(options) - _OPTIONS[method])}"
    if why is not None:
        return OCPResult(False, why, solve_time=time.perf_counter() - t_start, **base)
    if method == "slsqp":
        solver = solve_slsqp
    else:
        solver = solve_energy if pb.objective == "energy" else solve_fuel
    try:
        out = solver(pb, deadline, **options)
    except (ValueError, np.linalg.LinAlgError, FloatingPointError) as exc:
        return OCPResult(
            False, f"solver error: {exc}", solve_time=time.perf_counter() - t_start, **base
        )
    return result_of(pb, out, method, t_start)


def solve(
    position: Any,
    velocity: Any,
    mass: Any,
    *,
    method: str = DEFAULT_METHOD,
    objective: str = "energy",
    n_control: int = OCP_CONTROL_POINTS,
    timeout_s: float | None = None,
    limits: ThrustLimits = OCP_THRUST,
    **options: Any,
) -> OCPResult:
    """Solve Eq. 4 from (position m, velocity m/s, mass kg). Never raises for a bad request or a
    failed solve: `success` is False and `message` says why.

    options: for "slsqp" `exact_gradients` (default True; False = SciPy's finite differences, as
    the paper), `maxiter`, `ftol`; for "qp" `passes` (mass-profile passes), `final_passes`,
    `tf_tol_s`.
    """
    t_start = time.perf_counter()
    base = {"method": str(method), "objective": str(objective)}
    why = check_request(
        position,
        velocity,
        mass,
        method=method,
        objective=objective,
        n_control=n_control,
        timeout_s=timeout_s,
    )
    if why is not None:
        return OCPResult(False, why, solve_time=time.perf_counter() - t_start, **base)
    pb = Problem(position, velocity, mass, objective, int(n_control), limits)
    deadline = math.inf if timeout_s is None else t_start + float(timeout_s)
    return _solve_built(pb, str(method), deadline, t_start, None, options)
