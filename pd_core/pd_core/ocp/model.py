"""Optimal control problem of Eq. 4: open-loop thrust from an initial state to rest at the pad.

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
* Constraints: x(t_f) = 0, v(t_f) = 0, OCP_THRUST bounds. No altitude constraint (Sec. 2.1).

Inside the solvers the final state is computed in closed form: the velocity and position gains of
each step depend only on the mass at its start, a cumulative sum, so one vectorised pass replaces
the step loop (`_Model`, equal to `dynamics.step` to rounding, see the tests) and its exact
gradient is one reverse cumulative sum more. The reported `states` are re-flown with
`dynamics.step_scalar`, the code every environment uses.

Methods:

* "slsqp": the paper's SciPy SLSQP over the 241 variables, either with SciPy's default
  finite-difference gradients (`exact_gradients=False`, as the paper ran it) or with the
  analytic gradients below.
* "qp" (default): for a fixed t_f and a frozen mass profile the final state is linear in the
  control points and the axes decouple, so Eq. 4 becomes, per axis, a strictly convex QP with a
  tridiagonal Hessian, 2 terminal equalities and box bounds, solved by a primal-dual active-set
  (semismooth Newton) method in a handful of batched 82 x 82 solves. The mass profile is refreshed
  from the solution in SQP passes that linearise the terminal state with its exact Jacobian (mass
  sensitivity included, so a fixed point is a true KKT point of Eq. 4), and t_f is found as the
  root of the envelope derivative dJ*/dt_f. "fuel" uses the same scheme with an LP (HiGHS) over
  T = T+ - T- and a bounded scalar search over t_f, then, at the chosen t_f, an elastic
  trust-region SLP (`_fuel_slp`) with one-sided Jacobians at T = 0: the plain LP passes can cycle
  between two bang-bang vertices that each miss rest by up to ~1 m/s.
* Eq. 4 with the mass-dependent |T| of Eq. 3 is non-convex: burning a little sideways fuel
  lightens the lander, which pays off when T3 is saturated, so lateral thrust avoids 0 and there
  are several local optima whose costs differ by up to ~0.5 %. Both methods find local optima.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.linalg import solve_banded
from scipy.optimize import linprog, minimize, minimize_scalar

from pd_core import dynamics
from pd_core.config import (
    DRY_MASS_KG,
    DT_S,
    G0_MPS2,
    GRAVITY_MPS2,
    ISP_S,
    OCP_CONTROL_POINTS,
    OCP_THRUST,
    ThrustLimits,
)
from pd_core.dynamics import _PHI1, _PHI2  # the very series dynamics.step uses
from pd_core.state import check_state

EXHAUST_VELOCITY_MPS = ISP_S * G0_MPS2
METHODS = ("qp", "slsqp")
OBJECTIVES = ("energy", "fuel")
DEFAULT_METHOD = "qp"
# ours: the range searched for t_f. The Table 1/3 optima lie in 40-90 s; 300 s is far beyond any
# flight the fuel allows, 4 s far below what 12 kN can stop.
TF_MIN_S = 4.0
TF_MAX_S = 300.0
# ours: requests outside these are refused as absurd for this lander (state.check_state's bounds
# catch garbage; these catch requests the 11-12 kN lander cannot mean).
OCP_MAX_ABS_POSITION_M = 1e5
OCP_MAX_SPEED_MPS = 2e3
ENERGY_COST_SCALE = 1e-6  # reported energy cost in kN^2 s
# ours: a result counts as converged when the re-flown final state is this close to rest at 0.
SUCCESS_POSITION_M = 0.3
SUCCESS_VELOCITY_MPS = 0.02


def _deriv_coeffs(coeffs: tuple[float, ...]) -> tuple[float, ...]:
    """Coefficients (highest power first) of the derivative of a Horner polynomial."""
    deg = len(coeffs) - 1
    return tuple(c * (deg - i) for i, c in enumerate(coeffs[:-1]))


_DPHI1 = _deriv_coeffs(_PHI1)
_DPHI2 = _deriv_coeffs(_PHI2)


def _horner(coeffs: tuple[float, ...], z: np.ndarray) -> np.ndarray:
    out = np.full_like(z, coeffs[0])
    for c in coeffs[1:]:
        out *= z
        out += c
    return out


# --- Result ------------------------------------------------------------------------------------


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
        return _Grid.make(self.time_of_flight, len(self.thrust)).interp(self.thrust)


# --- Transcription -----------------------------------------------------------------------------


@dataclass(frozen=True)
class _Grid:
    """Integration steps of a flight of t_f seconds and their interpolation weights."""

    t_f: float
    n_control: int
    dt: np.ndarray  # (n,) step lengths, last one partial
    t0: np.ndarray  # (n,) step start times
    r: np.ndarray  # (n,) time remaining after each step
    j: np.ndarray  # (n,) left control point of each step's midpoint
    w1: np.ndarray  # (n,) weight of the right control point
    dw1: np.ndarray  # (n,) d w1 / d t_f
    starts: np.ndarray  # (n_control,) first step whose left control point is k (or n)

    @staticmethod
    def make(t_f: float, n_control: int, dt_s: float = DT_S) -> _Grid:
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
        starts = np.searchsorted(j, np.arange(n_control))
        return _Grid(t_f, n_control, dt, t0, r, j, w1, dw1, starts)

    def wt_mul(self, v: np.ndarray) -> np.ndarray:
        """W^T v for step values v (n, ...): the adjoint of `interp`, (n_control, ...).

        Segment sums over the sorted left indices (no BLAS: tiny multithreaded BLAS calls are
        100x slower on a busy machine).
        """
        shape = (-1,) + (1,) * (v.ndim - 1)
        pad = np.zeros((1,) + v.shape[1:])
        # A zero row at index n keeps every segment end in range: clipping the starts to n - 1
        # instead would end the last non-empty segment one step early and drop the last
        # (partial) step from the gradient of its two control points.
        a = np.concatenate([(1.0 - self.w1).reshape(shape) * v, pad])
        b = np.concatenate([self.w1.reshape(shape) * v, pad])
        n = len(self.dt)
        empty = np.diff(np.append(self.starts, n)) == 0
        sa = np.add.reduceat(a, self.starts, axis=0)
        sb = np.add.reduceat(b, self.starts, axis=0)
        sa[empty] = 0.0
        sb[empty] = 0.0
        out = sa
        out[1:] += sb[:-1]
        return out

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
        return (1.0 - self.w1)[:, None] * p[self.j] + self.w1[:, None] * p[self.j + 1]

    def interp_dtf(self, p: np.ndarray) -> np.ndarray:
        """d(step thrusts)/d t_f at fixed control points."""
        return self.dw1[:, None] * (p[self.j + 1] - p[self.j])


@dataclass(frozen=True)
class _Flight:
    """Closed-form flight of a thrust schedule: the per-step gains and the final state."""

    u: np.ndarray  # (n, 3) step thrusts
    m: np.ndarray  # (n,) mass at each step start
    z: np.ndarray  # (n,) burn / m
    k: np.ndarray  # (n,) velocity gain: v_{i+1} = v_i + g dt_i + k_i u_i
    h: np.ndarray  # (n,) position gain: x_{i+1} = x_i + dt_i v_i + g dt_i^2 / 2 + h_i u_i
    xf: np.ndarray
    vf: np.ndarray
    fuel: float


def _fly(p: np.ndarray, g: _Grid, x0: np.ndarray, v0: np.ndarray, m0: float) -> _Flight:
    u = g.interp(p)
    burn = np.abs(u).sum(axis=1) * g.dt / EXHAUST_VELOCITY_MPS
    cum = np.cumsum(burn)
    m = m0 - np.concatenate(([0.0], cum[:-1]))
    z = burn / m
    k = g.dt / m * _horner(_PHI1, z)
    h = g.dt * g.dt / m * _horner(_PHI2, z)
    t_f = g.t_f
    vf = v0 + GRAVITY_MPS2 * t_f + k @ u
    xf = x0 + v0 * t_f + 0.5 * GRAVITY_MPS2 * t_f**2 + (k * g.r + h) @ u
    return _Flight(u, m, z, k, h, xf, vf, float(cum[-1]))


def _objective_value(fl: _Flight, g: _Grid, objective: str) -> float:
    if objective == "energy":
        return float(g.dt @ (fl.u * fl.u).sum(axis=1))
    return fl.fuel


def _gradients(
    p: np.ndarray,
    g: _Grid,
    x0: np.ndarray,
    v0: np.ndarray,
    m0: float,
    objective: str,
    sign: float | None = None,
) -> tuple[float, np.ndarray, float, np.ndarray, np.ndarray, np.ndarray]:
    """(J, dJ/dp, dJ/dt_f, c, dc/dp (6, N, 3), dc/dt_f (6,)) with c = [x_f, v_f], exactly.

    `sign` (+1 or -1) replaces sign(u) = 0 in d|u|/du at the steps whose thrust is exactly 0:
    the one-sided derivatives at the kink of |u| in the mass, for a move of that sign (the fuel
    LP's T+ and T- columns; sign(0) = 0 would drop the mass effect of switching on a thrust that
    is 0 now, and the LP's bang-bang iterates are full of such zeros).

    Reverse mode by hand: each output depends on u_i directly through the gains and indirectly
    through the mass of every later step (m_l = m0 - sum_{j<l} burn_j), a reverse cumulative sum.
    """
    fl = _fly(p, g, x0, v0, m0)
    u, m, z, k, h, dt, r = fl.u, fl.m, fl.z, fl.k, fl.h, g.dt, g.r
    c_e = EXHAUST_VELOCITY_MPS
    mdot = np.abs(u).sum(axis=1) / c_e
    p1d = _horner(_DPHI1, z)
    p2d = _horner(_DPHI2, z)
    dk_dmdot = dt * dt / (m * m) * p1d
    dh_dmdot = dt**3 / (m * m) * p2d
    dk_dm = -(k + dt * p1d * z / m) / m
    dh_dm = -(h + dt * dt * p2d * z / m) / m
    gk = np.concatenate([u.T * r, u.T])  # adjoint of k_i for outputs x_f (3), v_f (3)
    gh = np.concatenate([u.T, np.zeros_like(u.T)])
    a_adj = gk * dk_dmdot + gh * dh_dmdot
    b_adj = gk * dk_dm + gh * dh_dm
    later = np.cumsum(b_adj[:, ::-1], axis=1)[:, ::-1] - b_adj  # sum over later steps
    mdot_adj = a_adj - dt * later
    sg = np.sign(u) if sign is None else np.where(u == 0.0, sign, np.sign(u))
    du = (mdot_adj / c_e)[:, :, None] * sg[None]
    cx = k * r + h
    for a in range(3):
        du[a, :, a] += cx
        du[3 + a, :, a] += k
    dc_dp = g.wt_mul(du.transpose(1, 0, 2)).transpose(1, 0, 2)
    dudtf = g.interp_dtf(p)
    # t_f enters through the explicit terms, the remaining times r_i (dr/dt_f = 1 but for the
    # last step), the interpolation weights and the length of the last step.
    mm, zz, dtl = m[-1], z[-1], dt[-1]
    dk_ddt = _horner(_PHI1, zz[None])[0] / mm + dtl / mm * p1d[-1] * mdot[-1] / mm
    dh_ddt = 2 * dtl * _horner(_PHI2, zz[None])[0] / mm + dtl**2 / mm * p2d[-1] * mdot[-1] / mm
    dr = np.ones_like(r)
    dr[-1] = 0.0
    dc_dtf = np.einsum("oib,ib->o", du, dudtf)
    dc_dtf[0:3] += v0 + GRAVITY_MPS2 * g.t_f + (k * dr) @ u
    dc_dtf[3:6] += GRAVITY_MPS2
    dc_dtf += gk[:, -1] * dk_ddt + gh[:, -1] * dh_ddt
    if objective == "energy":
        j_val = float(dt @ (u * u).sum(axis=1))
        dj_du = 2.0 * dt[:, None] * u
        dj_dtf = float((u[-1] ** 2).sum())
    else:
        j_val = fl.fuel
        dj_du = dt[:, None] * sg / c_e
        dj_dtf = float(np.abs(u[-1]).sum() / c_e)
    dj_dtf += float((dj_du * dudtf).sum())
    dj_dp = g.wt_mul(dj_du)
    c = np.concatenate([fl.xf, fl.vf])
    return j_val, dj_dp, dj_dtf, c, dc_dp, dc_dtf


def fly(
    x0: np.ndarray, v0: np.ndarray, m0: float, thrust_n: np.ndarray, t_f: float
) -> tuple[np.ndarray, np.ndarray]:
    """(states (n+1, 7), times (n+1,)) of the OCP schedule re-flown with `dynamics.step_scalar`."""
    g = _Grid.make(t_f, len(thrust_n))
    u = g.interp(np.asarray(thrust_n, dtype=float))
    states = np.empty((len(g.dt) + 1, 7))
    s: tuple[float, ...] = (*(float(v) for v in x0), *(float(v) for v in v0), float(m0))
    states[0] = s
    zero = (0.0, 0.0, 0.0)
    for i, (ui, dti) in enumerate(zip(u.tolist(), g.dt.tolist(), strict=True)):
        s = dynamics.step_scalar(s, tuple(ui), zero, dti)
        states[i + 1] = s
    return states, np.concatenate([g.t0, [t_f]])


# --- Request checks ----------------------------------------------------------------------------


def check_request(position: Any, velocity: Any, mass: Any) -> str | None:
    """None if (position m, velocity m/s, mass kg) is a request the OCP can take, else why not."""
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
    if pos[2] <= 0.0:
        return f"altitude must be > 0 m, got {pos[2]:g} m"
    if m[0] <= DRY_MASS_KG:
        return f"mass must exceed the dry mass {DRY_MASS_KG:g} kg, got {m[0]:g} kg"
    if np.abs(pos).max() > OCP_MAX_ABS_POSITION_M:
        return f"position beyond {OCP_MAX_ABS_POSITION_M:g} m is absurd for this lander"
    if np.linalg.norm(vel) > OCP_MAX_SPEED_MPS:
        return f"speed beyond {OCP_MAX_SPEED_MPS:g} m/s is absurd for this lander"
    return None


# --- Initial guess (Sec. 3.1) ------------------------------------------------------------------


def _constant_thrust_flight(
    x0: np.ndarray, v0: np.ndarray, m0: float, thrust: np.ndarray, t: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form (x(t), v(t)) under constant thrust (..., 3) with the rocket equation."""
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
    """(constant thrust (3,), t_f) of Sec. 3.1: Eq. 19 for T1, T2, grid search for t_f and T3.

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
    xf, vf = _constant_thrust_flight(x0, v0, m0, thr, tf)
    frac = np.linspace(0.0, 1.0, n_alt)
    xs, _ = _constant_thrust_flight(x0, v0, m0, thr[..., None, :], tf[..., None] * frac)
    ok = xs[..., 2].min(axis=-1) >= 0.0
    err = np.sqrt((xf**2).sum(-1) + (vf**2).sum(-1))
    err = np.where(ok, err, np.inf)
    if not np.isfinite(err).any():
        err = np.sqrt((xf**2).sum(-1) + (vf**2).sum(-1))
    i = np.unravel_index(np.argmin(err), err.shape)
    return thr[i], float(tf[i])


# --- SLSQP (the paper's method) ----------------------------------------------------------------

_T_SCALE_N = 1e4  # decision variables in units of 10 kN and 10 s keep SLSQP well conditioned
_TF_SCALE_S = 10.0
_C_SCALE = np.array([100.0, 100.0, 100.0, 10.0, 10.0, 10.0])  # m, m/s


class _Timeout(Exception):
    pass


def _solve_slsqp(
    x0: np.ndarray,
    v0: np.ndarray,
    m0: float,
    n_control: int,
    objective: str,
    limits: ThrustLimits,
    deadline: float,
    exact_gradients: bool = True,
    maxiter: int = 500,
    ftol: float = 1e-10,
    guess: tuple[np.ndarray, float] | None = None,
) -> tuple[np.ndarray, float, int, str, bool]:
    thr0, tf0 = initial_guess(x0, v0, m0, limits) if guess is None else guess
    p0 = np.tile(np.clip(thr0, limits.lo, limits.hi), (n_control, 1))
    y0 = np.concatenate([p0.ravel() / _T_SCALE_N, [tf0 / _TF_SCALE_S]])
    g0 = _Grid.make(tf0, n_control)
    j_scale = max(_objective_value(_fly(p0, g0, x0, v0, m0), g0, objective), 1.0)
    cache: dict[str, Any] = {}

    def unpack(y: np.ndarray) -> tuple[np.ndarray, float]:
        return y[:-1].reshape(n_control, 3) * _T_SCALE_N, float(y[-1]) * _TF_SCALE_S

    def evaluate(y: np.ndarray) -> dict[str, Any]:
        if time.perf_counter() > deadline:
            raise _Timeout
        key = y.tobytes()
        if cache.get("key") != key:
            p, t_f = unpack(y)
            g = _Grid.make(t_f, n_control)
            if exact_gradients:
                j, djp, djt, c, dcp, dct = _gradients(p, g, x0, v0, m0, objective)
                cache["grad"] = (djp, djt, dcp, dct)
            else:
                fl = _fly(p, g, x0, v0, m0)
                j, c = _objective_value(fl, g, objective), np.concatenate([fl.xf, fl.vf])
            cache.update(key=key, j=j, c=c)
        return cache

    def fun(y: np.ndarray) -> float:
        return evaluate(y)["j"] / j_scale

    def cons(y: np.ndarray) -> np.ndarray:
        return evaluate(y)["c"] / _C_SCALE

    def fun_jac(y: np.ndarray) -> np.ndarray:
        djp, djt, _, _ = evaluate(y)["grad"]
        return np.concatenate([djp.ravel() * _T_SCALE_N, [djt * _TF_SCALE_S]]) / j_scale

    def cons_jac(y: np.ndarray) -> np.ndarray:
        _, _, dcp, dct = evaluate(y)["grad"]
        jac = np.concatenate([dcp.reshape(6, -1) * _T_SCALE_N, dct[:, None] * _TF_SCALE_S], 1)
        return jac / _C_SCALE[:, None]

    bounds = [
        (lo / _T_SCALE_N, hi / _T_SCALE_N)
        for _ in range(n_control)
        for lo, hi in zip(limits.lo, limits.hi, strict=True)
    ] + [(TF_MIN_S / _TF_SCALE_S, TF_MAX_S / _TF_SCALE_S)]
    constraint: dict[str, Any] = {"type": "eq", "fun": cons}
    if exact_gradients:
        constraint["jac"] = cons_jac
    try:
        res = minimize(
            fun,
            y0,
            jac=fun_jac if exact_gradients else None,
            method="SLSQP",
            bounds=bounds,
            constraints=[constraint],
            options={"maxiter": maxiter, "ftol": ftol},
        )
    except _Timeout:
        return p0, tf0, 0, "timed out", False
    p, t_f = unpack(res.x)
    return p, t_f, int(res.nit), f"SLSQP: {res.message}", bool(res.success)


# --- Fast method: frozen-mass QP / LP in the control points, 1-D search over t_f -------------


def _tridiag_mul(main: np.ndarray, upper: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Q p for symmetric tridiagonal Q and p (..., N)."""
    out = main * p
    out[..., :-1] += upper * p[..., 1:]
    out[..., 1:] += upper * p[..., :-1]
    return out


def _pdas_qp(
    q_main: np.ndarray,
    q_upper: np.ndarray,
    jac: np.ndarray,
    rhs: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    active0: np.ndarray | None,
    max_iter: int = 40,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """min sum_axes p_a^T Q p_a s.t. sum_a J_a p_a = rhs (6 rows), lo_a <= p_a <= hi_a.

    Primal-dual active set (semismooth Newton): guess which bounds are active, solve the
    equality-constrained KKT system with those variables fixed, update the guess from the
    primal and dual violations; stops when the guess repeats (typically 2-5 solves). The KKT
    system is reduced by a Schur complement to 3 tridiagonal solves with 7 right-hand sides and
    one 6 x 6 solve. Q is given by its diagonals (tridiagonal, positive definite), jac (6, 3, N),
    rhs (6,), lo/hi (3,), active0 (3, N) in {-1, 0, 1}. Returns (p (3, N), lambda (6,),
    active, ok).
    """
    n = q_main.shape[0]
    act = np.zeros((3, n), dtype=np.int8) if active0 is None else active0.copy()
    jt = jac.transpose(1, 2, 0)  # (3, N, 6)
    lam = np.zeros(6)
    p = np.zeros((3, n))
    x = np.empty((3, n, 7))
    for _ in range(max_iter):
        free = (act == 0).astype(float)
        p_b = np.where(act > 0, hi[:, None], np.where(act < 0, lo[:, None], 0.0))
        r = np.concatenate(
            [(free * _tridiag_mul(q_main, q_upper, p_b))[..., None], free[..., None] * jt], -1
        )
        try:
            for ax in range(3):
                f = free[ax]
                ab = np.zeros((3, n))
                off = q_upper * f[:-1] * f[1:]
                ab[0, 1:] = off
                ab[1] = q_main * f + (1.0 - f)
                ab[2, :-1] = off
                x[ax] = solve_banded((1, 1), ab, r[ax], check_finite=False)
            s = 0.5 * np.einsum("oan,anp->op", jac, x[..., 1:])
            lam = np.linalg.solve(s, np.einsum("oan,an->o", jac, p_b - x[..., 0]) - rhs)
        except (np.linalg.LinAlgError, ValueError):
            return p, lam, act, False
        p = p_b - x[..., 0] - 0.5 * np.einsum("anp,p->an", x[..., 1:], lam)
        grad = 2.0 * _tridiag_mul(q_main, q_upper, p) + np.einsum("anp,p->an", jt, lam)
        fixed = act != 0
        new = np.zeros_like(act)
        new[(fixed & (act > 0) & (grad < 0)) | (~fixed & (p > hi[:, None]))] = 1
        new[(fixed & (act < 0) & (grad > 0)) | (~fixed & (p < lo[:, None]))] = -1
        if np.array_equal(new, act):
            return p, lam, act, True
        act = new
    return p, lam, act, False


@dataclass
class _FastState:
    """What one t_f evaluation hands the next: the linearisation point and the active set."""

    p: np.ndarray  # (N, 3) control points, N
    active: np.ndarray | None = None
    evals: int = 0


_KINK_OFFSET_N = 100.0
_KN = 1e3  # the QP and LP work in kN and kN^2 s for conditioning
_INFEASIBLE = (math.inf, -math.inf, None)


def _linearised(
    p: np.ndarray, g: _Grid, x0: np.ndarray, v0: np.ndarray, m0: float, objective: str
) -> tuple[np.ndarray, np.ndarray, tuple[Any, ...]]:
    """(J (6, 3, N) per kN, rhs (6,)) of c(p) + J (p' - p) = 0 with the exact Jacobian (mass
    sensitivity included, so the fixed point is the true optimum, not a frozen-mass one)."""
    grads = _gradients(p, g, x0, v0, m0, objective)
    dcp = grads[4]
    jac = dcp.transpose(0, 2, 1) * _KN
    rhs = np.einsum("oan,an->o", jac, p.T / _KN) - grads[3]
    return jac, rhs, grads


def _energy_at(
    t_f: float,
    st: _FastState,
    x0: np.ndarray,
    v0: np.ndarray,
    m0: float,
    limits: ThrustLimits,
    passes: int,
) -> tuple[float, float, np.ndarray | None]:
    """(J* kN^2 s, dJ*/dt_f, p) at fixed t_f: SQP passes of the PDAS QP; the derivative comes
    from the envelope theorem, dJ*/dt_f = dJ/dt_f + lambda . dc/dt_f at the optimum."""
    g = _Grid.make(t_f, st.p.shape[0])
    q_main, q_upper = g.hessian_diagonals()
    p, active = st.p, st.active
    lo, hi = limits.lo / _KN, limits.hi / _KN
    lam = np.zeros(6)
    for _ in range(passes):
        jac, rhs, _ = _linearised(p, g, x0, v0, m0, "energy")
        pk, lam, active, ok = _pdas_qp(q_main, q_upper, jac, rhs, lo, hi, active)
        if not ok:
            return _INFEASIBLE
        p_new = pk.T * _KN
        change = np.abs(p_new - p).max()
        p = p_new
        if change < 1e-2:
            break
    st.p, st.active = p, active
    st.evals += 1
    j, _, djt, _, _, dct = _gradients(p, g, x0, v0, m0, "energy")
    return j / _KN**2, djt / _KN**2 + float(lam @ dct), p


def _fuel_lp_at(
    t_f: float,
    st: _FastState,
    x0: np.ndarray,
    v0: np.ndarray,
    m0: float,
    limits: ThrustLimits,
    passes: int,
) -> tuple[float, float, np.ndarray | None]:
    """(fuel kg, nan, p) at fixed t_f: LP passes, min sum_k w_k (p+ + p-) over T = T+ - T- with
    w_k = sum_i dt_i W_ik / (Isp g0), the fuel when adjacent control points share a sign (an
    upper bound on it otherwise), subject to the linearised terminal constraints."""
    n = st.p.shape[0]
    g = _Grid.make(t_f, n)
    wsum = g.wt_mul(g.dt) / EXHAUST_VELOCITY_MPS
    c = np.tile(wsum, 6)  # [p+ axis 0, p- axis 0, p+ axis 1, ...]
    bnds = []
    for ax in range(3):
        lo, hi = limits.lo[ax] / _KN, limits.hi[ax] / _KN
        bnds += [(0.0, max(hi, 0.0))] * n + [(0.0, max(-lo, 0.0))] * n
    p = st.p
    for _ in range(passes):
        jac, rhs, _ = _linearised(p, g, x0, v0, m0, "fuel")
        a_eq = np.concatenate([jac, -jac], axis=2).reshape(6, 6 * n)
        res = linprog(c, A_eq=a_eq, b_eq=rhs, bounds=bnds, method="highs")
        if res.status != 0:
            return _INFEASIBLE
        xs = res.x.reshape(3, 2, n)
        p_new = (xs[:, 0] - xs[:, 1]).T * _KN
        change = np.abs(p_new - p).max()
        p = p_new
        if change < 1e-1:
            break
    st.p = p
    st.evals += 1
    return _fly(p, g, x0, v0, m0).fuel, math.nan, p


# Fuel SLP: elastic, trust-region sequential LP. The thrust is split T = T+ - T- (T+, T- >= 0)
# and the terminal state is linearised in each with its one-sided exact Jacobian (sign +1 for
# T+, -1 for T-), so switching on a thrust that is 0 now counts its mass effect. Slacks on the
# 6 linearised terminal rows keep every LP feasible; steps are accepted on the l1 merit
# fuel + mu |c| (mu above the multipliers, ~1 kg per m/s) and the box |T' - T| <= delta adapts.
_FUEL_MERIT_MU = np.array([50.0, 50.0, 50.0, 50.0, 50.0, 50.0])  # kg per m, kg per m/s
_FUEL_TR_MAX_ITER = 60


def _fuel_lp_step(
    p: np.ndarray,
    g: _Grid,
    x0: np.ndarray,
    v0: np.ndarray,
    m0: float,
    limits: ThrustLimits,
    delta_kn: float,
) -> tuple[np.ndarray, float, np.ndarray] | None:
    """One elastic LP of the SLP at control points p (N, 3) N within a box of delta_kn kN.

    Returns (p' (N, 3) N, predicted l1-merit reduction, c(p)), None if HiGHS fails.
    """
    n = p.shape[0]
    wsum = g.wt_mul(g.dt) / EXHAUST_VELOCITY_MPS
    jp = _gradients(p, g, x0, v0, m0, "fuel", sign=1.0)
    jm = _gradients(p, g, x0, v0, m0, "fuel", sign=-1.0)
    c_now = jp[3]
    a_plus = jp[4].transpose(0, 2, 1) * _KN  # (6, 3, N) per kN
    a_minus = -jm[4].transpose(0, 2, 1) * _KN
    cur = p.T / _KN
    pos, neg = np.maximum(cur, 0.0), np.maximum(-cur, 0.0)
    rhs = np.einsum("oan,an->o", a_plus, pos) + np.einsum("oan,an->o", a_minus, neg) - c_now
    # columns: [T+ axis 0, T- axis 0, T+ axis 1, ...] (6N), then slacks s+ (6), s- (6)
    a_thr = np.stack([a_plus, a_minus], axis=2).reshape(6, 6 * n)
    eye = np.eye(6)
    a_eq = np.concatenate([a_thr, eye, -eye], axis=1)
    cost = np.concatenate([np.tile(wsum, 6) * _KN, _FUEL_MERIT_MU, _FUEL_MERIT_MU])
    hi_pm = np.stack([np.maximum(limits.hi, 0.0), np.maximum(-limits.lo, 0.0)], 1) / _KN
    cur_pm = np.stack([pos, neg], axis=1)  # (3, 2, N)
    lb = np.maximum(cur_pm - delta_kn, 0.0).reshape(-1)
    ub = np.minimum(cur_pm + delta_kn, hi_pm[:, :, None]).reshape(-1)
    lb = np.minimum(lb, ub)
    bounds = np.stack(
        [np.concatenate([lb, np.zeros(12)]), np.concatenate([ub, np.full(12, np.inf)])], 1
    )
    res = linprog(cost, A_eq=a_eq, b_eq=rhs, bounds=bounds, method="highs")
    if res.status != 0:
        return None
    xs = res.x[: 6 * n].reshape(3, 2, n)
    p_new = (xs[:, 0] - xs[:, 1]).T * _KN
    lin_now = float(np.tile(wsum, 6) @ cur_pm.reshape(-1)) * _KN + _FUEL_MERIT_MU @ np.abs(c_now)
    return p_new, lin_now - float(res.fun), c_now


def _fuel_merit(fl: _Flight) -> float:
    return fl.fuel + float(_FUEL_MERIT_MU @ np.abs(np.concatenate([fl.xf, fl.vf])))


def _fuel_slp(
    p: np.ndarray,
    g: _Grid,
    x0: np.ndarray,
    v0: np.ndarray,
    m0: float,
    limits: ThrustLimits,
    max_iter: int,
    delta_kn: float = 4.0,
    tol_kg: float = 1e-6,
    deadline: float = math.inf,
) -> np.ndarray | None:
    """Trust-region SLP on fuel at fixed t_f from p (N, 3) N; the best control points found."""
    merit = _fuel_merit(_fly(p, g, x0, v0, m0))
    for _ in range(max_iter):
        if time.perf_counter() > deadline:
            raise _Timeout
        step = _fuel_lp_step(p, g, x0, v0, m0, limits, delta_kn)
        if step is None:
            return None
        p_new, pred, _ = step
        merit_new = _fuel_merit(_fly(p_new, g, x0, v0, m0))
        actual = merit - merit_new
        if pred <= tol_kg * max(merit, 1.0):
            break  # the linearised merit cannot improve: a KKT point of the l1 problem
        if actual >= 0.1 * pred:
            moved = np.abs(p_new - p).max() / _KN
            p, merit = p_new, merit_new
            if actual >= 0.75 * pred and moved >= 0.99 * delta_kn:
                delta_kn = min(2.0 * delta_kn, 24.0)
        else:
            delta_kn *= 0.25
            if delta_kn < 1e-6:
                break
    return p


def _solve_fast(
    x0: np.ndarray,
    v0: np.ndarray,
    m0: float,
    n_control: int,
    objective: str,
    limits: ThrustLimits,
    deadline: float,
    passes: int = 2,
    final_passes: int = 8,
    tf_tol_s: float = 2e-3,
) -> tuple[np.ndarray, float, int, str, bool]:
    thr0, tf0 = initial_guess(x0, v0, m0, limits, np.arange(10.0, 150.01, 5.0), 13)
    # A lateral thrust of exactly 0 sits on the kink of |T| in Eq. 3: there the energy optimum is
    # a saddle (burning a little sideways fuel lightens the lander and pays off when T3 is
    # saturated), and the linearisation, sign(0) = 0, cannot leave it. Start off the kink.
    thr0 = thr0.copy()
    thr0[:2] = np.where(np.abs(thr0[:2]) < _KINK_OFFSET_N, _KINK_OFFSET_N, thr0[:2])
    st = _FastState(np.tile(thr0, (n_control, 1)))
    at = _energy_at if objective == "energy" else _fuel_lp_at

    def f(t_f: float, n_pass: int = passes) -> tuple[float, float, np.ndarray | None]:
        if time.perf_counter() > deadline:
            raise _Timeout
        return at(t_f, st, x0, v0, m0, limits, n_pass)

    try:
        if objective == "energy":
            t_f = _tf_root(f, tf0, tf_tol_s)
        else:
            t_f = _tf_golden(f, tf0, tf_tol_s * 5)
        val, _, p = (math.inf, 0.0, None) if t_f is None else f(t_f, final_passes)
        if objective == "fuel" and p is not None and t_f is not None:
            # The plain LP passes can cycle between two bang-bang vertices that each miss rest
            # (up to ~1 m/s); the trust-region SLP converges to a schedule that reaches it.
            g = _Grid.make(t_f, n_control)
            p = _fuel_slp(p, g, x0, v0, m0, limits, _FUEL_TR_MAX_ITER, deadline=deadline)
            val = math.inf if p is None else _fly(p, g, x0, v0, m0).fuel
    except _Timeout:
        return st.p, tf0, st.evals, "timed out", False
    if t_f is None or p is None or not math.isfinite(val):
        return st.p, tf0, st.evals, "no feasible thrust schedule in the searched t_f range", False
    return p, t_f, st.evals, "converged", True


def _tf_root(f: Any, tf0: float, tol_s: float) -> float | None:
    """t_f where dJ*/dt_f = 0: secant steps on the envelope derivative from the guess until the
    root is bracketed (an infeasible t_f counts as too short), then Illinois false position.

    J* is flat at its minimum (J'' ~ J / t_f^2), so tol_s = 0.02 s moves the cost by < 1e-6.
    """
    a = tf0
    _, da, p = f(a)
    while p is None and a < TF_MAX_S:
        a = min(a * 1.25, TF_MAX_S)
        _, da, p = f(a)
    if p is None:
        return None
    b = a * (1.1 if da < 0 else 1 / 1.1)
    _, db, _ = f(b)
    for _ in range(20):
        if (da < 0) != (db < 0):
            break
        # secant extrapolation towards the root, at least 5 % and at most 2x further
        slope = (db - da) / (b - a) if math.isfinite(db) else 0.0
        step = -db / slope if slope > 0 else math.copysign(0.3 * b, -db)
        step = math.copysign(min(max(abs(step), 0.05 * b), 1.0 * b), step)
        a, da = b, db
        b = min(max(b + step, TF_MIN_S), TF_MAX_S)
        _, db, _ = f(b)
        if b in (TF_MIN_S, TF_MAX_S) and (db < 0) == (da < 0):
            return b
    # Illinois false position on the stored bracket (never re-evaluates an end: with warm
    # starts a re-evaluation can differ in the last digits and flip a sign Brent relies on).
    side = 0
    for _ in range(40):
        if abs(b - a) <= tol_s:
            break
        if math.isfinite(da) and math.isfinite(db) and db != da:
            c = b - db * (b - a) / (db - da)
            if not min(a, b) < c < max(a, b):
                c = 0.5 * (a + b)
        else:
            c = 0.5 * (a + b)
        _, dc, _ = f(c)
        if (dc < 0) == (db < 0):
            b, db = c, dc
            if side == -1:
                da *= 0.5
            side = -1
        else:
            a, da = b, db
            b, db = c, dc
            side = 1
    return 0.5 * (a + b) if abs(b - a) <= tol_s else b


def _tf_golden(f: Any, tf0: float, tol_s: float) -> float | None:
    """t_f minimising the fuel LP value by a bounded Brent search around the guess; infeasible
    t_f (too short) get a penalty that falls with t_f so the search walks out of them."""

    def val(t: float) -> float:
        v, _, p = f(t)
        return 1e6 - t if p is None else v

    res = minimize_scalar(
        val,
        bounds=(max(TF_MIN_S, 0.5 * tf0), min(TF_MAX_S, 2.0 * tf0)),
        method="bounded",
        options={"xatol": tol_s},
    )
    return float(res.x) if res.fun < 1e5 else None


# --- Public entry point ------------------------------------------------------------------------


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
    the paper), `maxiter`, `ftol`; for "qp" `passes` (mass-profile passes), `tf_tol_s`.
    """
    t_start = time.perf_counter()
    base = {"method": str(method), "objective": str(objective)}
    why = check_request(position, velocity, mass)
    if why is None and method not in METHODS:
        why = f"unknown method {method!r}; choose one of {', '.join(METHODS)}"
    if why is None and objective not in OBJECTIVES:
        why = f"unknown objective {objective!r}; choose one of {', '.join(OBJECTIVES)}"
    if why is None and (not isinstance(n_control, (int, np.integer)) or n_control < 2):
        why = f"n_control must be an integer >= 2, got {n_control!r}"
    if why is None and timeout_s is not None and not timeout_s > 0:
        why = f"timeout_s must be > 0 s, got {timeout_s!r}"
    allowed = {
        "slsqp": {"exact_gradients", "maxiter", "ftol"},
        "qp": {"passes", "final_passes", "tf_tol_s"},
    }
    if why is None and set(options) - allowed[method]:
        why = f"unknown option(s) for {method}: {sorted(set(options) - allowed[method])}"
    if why is not None:
        return OCPResult(False, why, solve_time=time.perf_counter() - t_start, **base)
    x0 = np.asarray(position, dtype=float).reshape(3)
    v0 = np.asarray(velocity, dtype=float).reshape(3)
    m0 = float(np.asarray(mass, dtype=float).reshape(-1)[0])
    deadline = math.inf if timeout_s is None else t_start + float(timeout_s)
    solver = _solve_slsqp if method == "slsqp" else _solve_fast
    try:
        p, t_f, iters, msg, ok = solver(
            x0, v0, m0, int(n_control), objective, limits, deadline, **options
        )
    except (ValueError, np.linalg.LinAlgError, FloatingPointError) as exc:
        return OCPResult(
            False, f"solver error: {exc}", solve_time=time.perf_counter() - t_start, **base
        )
    states, times = fly(x0, v0, m0, p, t_f)
    g = _Grid.make(t_f, int(n_control))
    fl = _fly(p, g, x0, v0, m0)
    cost = _objective_value(fl, g, objective)
    cost = cost * ENERGY_COST_SCALE if objective == "energy" else cost
    pos_err = float(np.linalg.norm(states[-1, 0:3]))
    vel_err = float(np.linalg.norm(states[-1, 3:6]))
    reached = pos_err <= SUCCESS_POSITION_M and vel_err <= SUCCESS_VELOCITY_MPS
    if ok and not reached:
        msg = (
            f"{msg}; final state misses rest at the pad: |x_f| {pos_err:.3g} m, "
            f"|v_f| {vel_err:.3g} m/s"
        )
    if not np.all(np.isfinite(states)):
        reached = False
        msg = f"{msg}; non-finite states"
    return OCPResult(
        success=bool(ok and reached),
        message=msg,
        time_of_flight=t_f,
        fuel=float(m0 - states[-1, 6]),
        cost=float(cost),
        thrust=p,
        control_times=np.linspace(0.0, t_f, int(n_control)),
        states=states,
        state_times=times,
        solve_time=time.perf_counter() - t_start,
        iterations=iters,
        **base,
    )
