"""The optimal-control problem of Eq. 4 as an object: built (and checked) once, solved many times.

Transcription (Sec. 3.1, with the choices the paper leaves open made explicit):

* Decision variables: `n_control` (80) thrust vectors at control times linspace(0, t_f, n) and the
  time of flight t_f: 3 * 80 + 1 = 241 variables, as the paper.
* Steps: whole dt = 0.2 s steps and one final partial step of length t_f - n_full dt in (0, dt],
  so the final state is a continuous function of t_f (a whole-steps-only transcription makes t_f
  a staircase that gradient methods cannot move). Every step is flown by `pd_core.dynamics`' exact
  constant-thrust step.
* Thrust: linearly interpolated between the control points and evaluated at each step's midpoint,
  held constant over the step (what `dynamics.step` integrates exactly).
* Objective "energy" (Eq. 4): the dt-weighted sum sum_i dt_i |T_i|^2, i.e. the integral of
  |T|^2 over the flight, continuous in t_f (a plain per-step sum would jump by |T|^2 whenever a
  step is added). Reported `cost` is in kN^2 s. Objective "fuel": the mass actually burned,
  sum_i dt_i sum_m |T_m,i| / (Isp g0) (kg).
* Constraints: x(t_f) = 0, v(t_f) = 0, thrust bounds. No altitude constraint (Sec. 2.1).

Inside the solvers the final state is computed in closed form (`Problem.fly`): the velocity and
position gains of each step depend only on the mass at its start, a cumulative sum, so one
vectorised pass replaces the step loop (equal to `dynamics.step` to rounding, see the tests), and
its exact gradient (`Problem.gradients`) is one reverse cumulative sum more. Reported states are
re-flown with `dynamics.step_scalar` (`Problem.simulate`), the code every environment uses.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np

from pd_core import dynamics
from pd_core.config import (
    DT_S,
    G0_MPS2,
    GRAVITY_MPS2,
    ISP_S,
    OCP_CONTROL_POINTS,
    OCP_THRUST,
    ThrustLimits,
)
from pd_core.dynamics import PHI1, PHI2
from pd_core.ocp import kernels
from pd_core.ocp.request import MAX_CONTROL_POINTS, check_request

EXHAUST_VELOCITY_MPS = ISP_S * G0_MPS2  # Eq. 3
# ours: the range searched for t_f. The Table 1/3 optima lie in 40-90 s; 300 s is far beyond any
# flight the fuel allows, 4 s far below what 12 kN can stop.
TF_MIN_S = 4.0
TF_MAX_S = 300.0
KN = 1e3  # the QP and LP work in kN and kN^2 s for conditioning


def _deriv_coeffs(coeffs: tuple[float, ...]) -> tuple[float, ...]:
    """Coefficients (highest power first) of the derivative of a Horner polynomial."""
    deg = len(coeffs) - 1
    return tuple(c * (deg - i) for i, c in enumerate(coeffs[:-1]))


_ARANGE = np.arange(MAX_CONTROL_POINTS, dtype=float)


def control_times(t_f: float, n: int) -> np.ndarray:
    """The n control times (s) of a plan of t_f s: np.linspace(0, t_f, n) to the bit (i * step,
    the last one t_f), without its per-call overhead (the teacher takes several a re-plan)."""
    if not 2 <= n <= MAX_CONTROL_POINTS:
        return np.linspace(0.0, t_f, n)
    t = _ARANGE[:n] * (t_f / (n - 1))
    t[-1] = t_f
    return t


# the phi series of `pd_core.dynamics` and their derivatives (leading 0), as the kernels take them
PHI_SERIES = np.array([PHI1, PHI2, (0.0, *_deriv_coeffs(PHI1)), (0.0, *_deriv_coeffs(PHI2))])


@dataclass(frozen=True)
class Grid:
    """Integration steps of a flight of t_f seconds and their interpolation weights."""

    t_f: float
    n_control: int
    dt: np.ndarray  # (n,) step lengths, last one partial
    t0: np.ndarray  # (n,) step start times
    r: np.ndarray  # (n,) time remaining after each step
    j: np.ndarray  # (n,) left control point of each step's midpoint
    w1: np.ndarray  # (n,) weight of the right control point
    dw1: np.ndarray  # (n,) d w1 / d t_f

    @staticmethod
    def make(t_f: float, n_control: int, dt_s: float = DT_S) -> Grid:
        n = max(1, math.ceil(t_f / dt_s - 1e-6))
        t0 = np.arange(n) * dt_s
        dt = np.full(n, dt_s)
        dt[-1] = t_f - t0[-1]
        mid = t0 + 0.5 * dt
        s = mid * (n_control - 1) / t_f
        j = np.minimum(np.floor(s).astype(np.int64), n_control - 2)
        w1 = s - j
        dmid = np.zeros(n)
        dmid[-1] = 0.5
        dw1 = (n_control - 1) * (dmid * t_f - mid) / t_f**2
        r = t_f - (t0 + dt)
        r[-1] = 0.0
        return Grid(t_f, n_control, dt, t0, r, j, w1, dw1)

    def wt_mul(self, v: np.ndarray) -> np.ndarray:
        """W^T v for step values v (n, ...): the adjoint of `interp`, (n_control, ...)
        (`kernels.wt_mul`: sums by left control point, no BLAS)."""
        flat = np.ascontiguousarray(v, dtype=float).reshape(len(self.dt), -1)
        out = kernels.wt_mul(self.j, self.w1, self.n_control, flat)
        return out.reshape((self.n_control,) + v.shape[1:])

    def hessian_diagonals(self) -> tuple[np.ndarray, np.ndarray]:
        """(main, upper) diagonals of Q = W^T diag(dt) W: sum_i dt_i |u_i|^2 = sum_a p_a^T Q p_a.

        Q is tridiagonal because each step interpolates two neighbouring control points.
        """
        n, a, b = self.n_control, 1.0 - self.w1, self.w1
        main = np.bincount(self.j, self.dt * a * a, n) + np.bincount(self.j + 1, self.dt * b * b, n)
        upper = np.bincount(self.j, self.dt * a * b, n)[:-1]
        return main, upper

    def interp(self, p: np.ndarray) -> np.ndarray:
        """Step thrusts (n, 3) from control points (n_control, 3)."""
        return kernels.interp(np.ascontiguousarray(p, dtype=float), self.j, self.w1)

    def interp_dtf(self, p: np.ndarray) -> np.ndarray:
        """d(step thrusts)/d t_f at fixed control points."""
        return self.dw1[:, None] * (p[self.j + 1] - p[self.j])


@dataclass(frozen=True)
class Flight:
    """Closed-form flight of a thrust schedule: the per-step gains and the final state."""

    u: np.ndarray  # (n, 3) step thrusts
    m: np.ndarray  # (n,) mass at each step start
    z: np.ndarray  # (n,) burn / m
    k: np.ndarray  # (n,) velocity gain: v_{i+1} = v_i + g dt_i + k_i u_i
    h: np.ndarray  # (n,) position gain: x_{i+1} = x_i + dt_i v_i + g dt_i^2 / 2 + h_i u_i
    xf: np.ndarray
    vf: np.ndarray
    fuel: float


class Gradients(NamedTuple):
    """Objective, terminal state c = [x_f, v_f] and their exact derivatives."""

    j: float  # objective (N^2 s for energy, kg for fuel)
    dj_dp: np.ndarray  # (n_control, 3)
    dj_dtf: float
    c: np.ndarray  # (6,) m, m/s
    dc_dp: np.ndarray  # (6, n_control, 3)
    dc_dtf: np.ndarray  # (6,)


@dataclass(frozen=True, eq=False)
class Problem:
    """Eq. 4 from one initial state: fixed data, checked once when built (ValueError if bad).

    Solvers (`pd_core.ocp.qp`, `.fuel`, `.slsqp`) take it and never re-check; `at` gives the
    same problem from another state (the receding-horizon teacher re-plans with it).
    """

    x0: np.ndarray  # (3,) m
    v0: np.ndarray  # (3,) m/s
    m0: float  # kg
    objective: str = "energy"
    n_control: int = OCP_CONTROL_POINTS
    limits: ThrustLimits = field(default=OCP_THRUST)

    def __post_init__(self) -> None:
        why = check_request(
            self.x0, self.v0, self.m0, objective=self.objective, n_control=self.n_control
        )
        if why is not None:
            raise ValueError(why)
        object.__setattr__(self, "x0", np.asarray(self.x0, dtype=float).reshape(3).copy())
        object.__setattr__(self, "v0", np.asarray(self.v0, dtype=float).reshape(3).copy())
        object.__setattr__(self, "m0", float(np.asarray(self.m0, dtype=float).reshape(-1)[0]))
        object.__setattr__(self, "n_control", int(self.n_control))

    def at(self, state: np.ndarray, n_control: int | None = None) -> Problem:
        """The same problem from state [x, v, m] (7,), optionally with other control points."""
        s = np.asarray(state, dtype=float)
        n = self.n_control if n_control is None else n_control
        return replace(self, x0=s[0:3], v0=s[3:6], m0=float(s[6]), n_control=n)

    def grid(self, t_f: float) -> Grid:
        return Grid.make(t_f, self.n_control)

    def fly(self, p: np.ndarray, g: Grid) -> Flight:
        """Closed-form flight of control points p (n_control, 3) N over grid g."""
        u = g.interp(p)
        m, z, k, h, fuel = kernels.flight(u, g.dt, self.m0, EXHAUST_VELOCITY_MPS, PHI_SERIES)
        c = kernels.final_state(u, k, h, g.r, g.t_f, self.x0, self.v0, GRAVITY_MPS2)
        return Flight(u, m, z, k, h, c[0:3], c[3:6], fuel)

    def altitudes(self, fl: Flight, g: Grid) -> np.ndarray:
        """Altitude (m) at the end of every step of a flight: Eq. 4 has no altitude constraint
        (Sec. 2.1), so a plan may pass below the ground; callers that fly it check this."""
        gz = float(GRAVITY_MPS2[2])
        return kernels.altitudes(fl.u, fl.k, fl.h, g.dt, self.x0[2], self.v0[2], gz)

    def cost(self, fl: Flight, g: Grid) -> float:
        """Objective of a flight: N^2 s ("energy") or kg ("fuel")."""
        if self.objective == "energy":
            return float(g.dt @ (fl.u * fl.u).sum(axis=1))
        return fl.fuel

    def gradients(
        self, p: np.ndarray, g: Grid, sign: float | None = None, fl: Flight | None = None
    ) -> Gradients:
        """Objective and terminal state with their exact derivatives in p and t_f; `fl`, if
        given, is `self.fly(p, g)` already computed (callers that need the flight too).

        `sign` (+1 or -1) replaces sign(u) = 0 in d|u|/du at the steps whose thrust is exactly 0:
        the one-sided derivatives at the kink of |u| in the mass, for a move of that sign (the
        fuel LP's T+ and T- columns; sign(0) = 0 would drop the mass effect of switching on a
        thrust that is 0 now, and the LP's bang-bang iterates are full of such zeros).
        """
        if fl is None:
            fl = self.fly(p, g)
        du, dc_dtf_u, sg, mdot = kernels.terminal_adjoint(
            fl.u,
            fl.m,
            fl.z,
            fl.k,
            fl.h,
            g.dt,
            g.r,
            math.nan if sign is None else sign,
            EXHAUST_VELOCITY_MPS,
            PHI_SERIES,
        )
        dc_dp = g.wt_mul(du).transpose(1, 0, 2)
        dudtf = g.interp_dtf(p)
        dc_dtf = np.einsum("iob,ib->o", du, dudtf) + dc_dtf_u
        dr = np.ones_like(g.r)
        dr[-1] = 0.0
        dc_dtf[0:3] += self.v0 + GRAVITY_MPS2 * g.t_f + (fl.k * dr) @ fl.u
        dc_dtf[3:6] += GRAVITY_MPS2
        u, dt = fl.u, g.dt
        if self.objective == "energy":
            j_val = float(dt @ (u * u).sum(axis=1))
            dj_du = 2.0 * dt[:, None] * u
            dj_dtf = float((u[-1] ** 2).sum())
        else:
            j_val = fl.fuel
            dj_du = dt[:, None] * sg / EXHAUST_VELOCITY_MPS
            dj_dtf = float(mdot[-1])
        dj_dtf += float((dj_du * dudtf).sum())
        c = np.concatenate([fl.xf, fl.vf])
        return Gradients(j_val, g.wt_mul(dj_du), dj_dtf, c, dc_dp, dc_dtf)

    def linearised(
        self, p: np.ndarray, g: Grid, sign: float | None = None, fl: Flight | None = None
    ) -> tuple[np.ndarray, np.ndarray, Gradients]:
        """(J (6, 3, N) per kN, rhs (6,)) of c(p) + J (p' - p) = 0 with the exact Jacobian
        (mass sensitivity included, so a fixed point is the true optimum, not a frozen-mass one);
        `fl` as in `gradients`.
        """
        grads = self.gradients(p, g, sign, fl)
        jac = grads.dc_dp.transpose(0, 2, 1) * KN
        rhs = np.einsum("oan,an->o", jac, p.T / KN) - grads.c
        return jac, rhs, grads

    def simulate(self, thrust_n: np.ndarray, t_f: float) -> tuple[np.ndarray, np.ndarray]:
        """(states (n+1, 7), times (n+1,)) of control points re-flown with `step_scalar`."""
        return fly(self.x0, self.v0, self.m0, thrust_n, t_f)


def fly(
    x0: np.ndarray, v0: np.ndarray, m0: float, thrust_n: np.ndarray, t_f: float
) -> tuple[np.ndarray, np.ndarray]:
    """(states (n+1, 7), times (n+1,)) of the OCP schedule re-flown with `dynamics.step_scalar`."""
    g = Grid.make(t_f, len(thrust_n))
    u = g.interp(np.asarray(thrust_n, dtype=float))
    states = np.empty((len(g.dt) + 1, 7))
    s: tuple[float, ...] = (*(float(v) for v in x0), *(float(v) for v in v0), float(m0))
    states[0] = s
    zero = (0.0, 0.0, 0.0)
    for i, (ui, dti) in enumerate(zip(u.tolist(), g.dt.tolist(), strict=True)):
        s = dynamics.step_scalar(s, tuple(ui), zero, dti)
        states[i + 1] = s
    return states, np.concatenate([g.t0, [t_f]])


class SolverOutput(NamedTuple):
    """What every solver returns to `solve()`: control points, t_f and how it went."""

    p: np.ndarray  # (n_control, 3) N
    t_f: float  # s
    iterations: int
    message: str
    ok: bool


class SolveTimeout(Exception):
    """Raised inside a solver when its deadline (time.perf_counter) has passed."""
