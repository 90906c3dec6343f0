"""Fast method, fuel objective: LP passes in the control points, Brent's method on t_f, SLP polish.

At fixed t_f, min sum_k w_k (p+ + p-) over T = T+ - T- (HiGHS) subject to the terminal state
linearised with its exact Jacobian; t_f minimises that value by Brent's bounded method. Plain LP
passes can cycle between two bang-bang vertices that each miss rest by up to ~1 m/s, so at the
chosen t_f an elastic trust-region SLP (`fuel_slp`) with one-sided Jacobians at T = 0 converges
to a schedule that reaches it.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import highspy
import numpy as np
from scipy.optimize import minimize_scalar

from pd_core.config import GRAVITY_MPS2
from pd_core.envelope import descent_limits
from pd_core.ocp import kernels
from pd_core.ocp.lp import solve_lp
from pd_core.ocp.model import (
    EXHAUST_VELOCITY_MPS,
    KN,
    PHI_SERIES,
    TF_MAX_S,
    TF_MIN_S,
    Flight,
    Grid,
    Problem,
    SolverOutput,
    SolveTimeout,
    control_times,
)
from pd_core.ocp.qp import INFEASIBLE, TfEval, WarmStart, free_final_time

# SLP: the thrust is split T = T+ - T- (T+, T- >= 0) and the terminal state is linearised in
# each with its one-sided exact Jacobian (sign +1 for T+, -1 for T-), so switching on a thrust
# that is 0 now counts its mass effect. Slacks on the 6 linearised terminal rows keep every LP
# feasible; steps are accepted on the l1 merit fuel + mu |c| (mu above the multipliers, ~1 kg
# per m/s) and the box |T' - T| <= delta adapts.
_MERIT_MU = np.full(6, 50.0)  # kg per m, kg per m/s
SLP_MAX_ITER = 60


def fuel_weights(g: Grid) -> np.ndarray:
    """w_k = sum_i dt_i W_ik / (Isp g0) (kg per N of control point k): the fuel of a schedule
    whose adjacent control points share a sign (an upper bound on it otherwise)."""
    return g.wt_mul(g.dt) / EXHAUST_VELOCITY_MPS


@dataclass(frozen=True)
class BrakeEnvelope:
    """A braking envelope on the plan (the receding-horizon teacher's; ours): at the end of
    every `every`-th step (and the last 10), descent speed <= v_max(z + gate_m, m) - margin_mps
    with v_max the runtime layer's braking limit for the force thrust_margin x T_max
    (`pd_core.envelope.descent_limits`: at the mass now, or counting on the mass lost while
    braking where `mass_loss`; z is the altitude above the plan's target, gate_m below the
    pad's altitude). At the mass now, a plan inside it keeps the vertical reserve the layer
    counts on at the mass it has *now*, not at the lighter mass it will have when it brakes.
    Linearised at the current plan (mass frozen), as the floor."""

    thrust_margin: float
    max_vertical_thrust_n: float
    land_speed_mps: float
    margin_mps: float = 0.7
    gate_m: float = 0.0
    every: int = 2
    elastic_kg_per_mps: float = 20.0  # cost of a row's violation in the LP (see fuel_lp_plan)
    mass_loss: bool = False

    def limits(self, altitude_m: np.ndarray, mass_kg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(v_max, dv_max/dz) at the altitudes above the pad (n,) and masses (n,)."""
        force = self.thrust_margin * self.max_vertical_thrust_n
        g = -float(GRAVITY_MPS2[2])
        return descent_limits(altitude_m, mass_kg, force, self.land_speed_mps, g, self.mass_loss)


def envelope_excess(pb: Problem, g: Grid, p: np.ndarray, env: BrakeEnvelope) -> float:
    """Worst step's descent speed beyond v_max - margin of `env` (m/s; <= 0: inside)."""
    fl = pb.fly(p, g)
    gz = float(GRAVITY_MPS2[2])
    vz = pb.v0[2] + np.cumsum(gz * g.dt + fl.k * fl.u[:, 2])
    zt = np.maximum(pb.altitudes(fl, g) + env.gate_m, 0.0)
    m_end = pb.m0 - np.cumsum(np.abs(fl.u).sum(axis=1) * g.dt / EXHAUST_VELOCITY_MPS)
    vmax, _ = env.limits(zt, m_end)
    return float((-vz - vmax + np.minimum(env.margin_mps, 0.5 * vmax)).max())


def _envelope_rows(
    pb: Problem, g: Grid, p: np.ndarray, env: BrakeEnvelope, fl: Flight
) -> tuple[np.ndarray, np.ndarray]:
    """(rows (m, 6N) per kN, lower bounds (m,)) of v_z + v_max(z, m) >= margin (`BrakeEnvelope`)
    linearised at p (flight `fl` = pb.fly(p, g)): v_z and z are linear in the vertical thrust
    with the mass frozen (dv_i/du_j = k_j, dz_i/du_j = h_j + k_j (t_i - t_j) for j <= i), v_max
    in z."""
    n_steps, n = len(g.dt), pb.n_control
    sel = np.union1d(
        np.arange(env.every - 1, n_steps, env.every), np.arange(max(n_steps - 10, 0), n_steps)
    )
    t_end = np.cumsum(g.dt)
    gz = float(GRAVITY_MPS2[2])
    vz = pb.v0[2] + np.cumsum(gz * g.dt + fl.k * fl.u[:, 2])
    z = pb.altitudes(fl, g)
    m_end = pb.m0 - np.cumsum(np.abs(fl.u).sum(axis=1) * g.dt / EXHAUST_VELOCITY_MPS)
    zt = np.maximum(z + env.gate_m, 0.0)
    vmax, dvmax = env.limits(zt, m_end)
    sel_t = t_end[sel, None]
    before = np.arange(n_steps)[None, :] <= sel[:, None]
    coef = fl.k[None, :] + dvmax[sel, None] * (fl.h[None, :] + fl.k[None, :] * (sel_t - t_end))
    coef *= before
    c_ctrl = g.wt_mul(coef.T).T * KN  # (m, n_control) per kN of vertical control point
    rows = np.zeros((len(sel), 6 * n))
    rows[:, 4 * n : 5 * n] = c_ctrl
    rows[:, 5 * n :] = -c_ctrl
    now = vz[sel] + dvmax[sel] * z[sel]
    margin = np.minimum(env.margin_mps, 0.5 * vmax[sel])  # at rest the limit is land_speed
    lower = margin - vmax[sel] + dvmax[sel] * z[sel] - now + c_ctrl @ (p[:, 2] / KN)
    return rows, lower


def fuel_lp_plan(
    pb: Problem,
    g: Grid,
    p: np.ndarray,
    passes: int,
    highs: highspy.Highs | None = None,
    floor_every: int = 0,
    envelope: BrakeEnvelope | None = None,
    lateral_settle_s: float = 0.0,
) -> np.ndarray | None:
    """Control points (N, 3) N after up to `passes` LP passes from p at the fixed t_f of grid g,
    min sum_k w_k (p+ + p-) subject to the linearised terminal constraints (and, with
    `floor_every`, altitude >= 0 at every floor_every-th step; with `envelope`, the braking
    envelope, elastic); None if an LP is infeasible.

    With `lateral_settle_s` > 0 the horizontal control points at or after t_f -
    lateral_settle_s are held at 0 N: with no horizontal gravity the horizontal velocity is then
    constant from the first held point on (within one control spacing after t_f -
    lateral_settle_s), so the terminal rows (rest on the target) put the lander at rest above
    it from there, and only the vertical axis flies the end.
    The receding-horizon teacher calls this with passes=1 and its own `highs`."""
    n = pb.n_control
    c = np.tile(fuel_weights(g), 6)  # [p+ axis 0, p- axis 0, p+ axis 1, ...]
    hi_pm = np.stack([np.maximum(pb.limits.hi, 0.0), np.maximum(-pb.limits.lo, 0.0)], 1) / KN
    ub = np.repeat(hi_pm.reshape(-1), n)
    if lateral_settle_s > 0.0:
        settled = control_times(g.t_f, n) >= g.t_f - lateral_settle_s
        ub = ub.reshape(3, 2, n)
        ub[0:2, :, settled] = 0.0
        ub = ub.reshape(-1)
    lb = np.zeros(6 * n)
    for _ in range(passes):
        # the terminal rows and the floor's, linearised at p in one compiled pass
        a_eq, rhs, row_hi = kernels.lp_rows(
            np.ascontiguousarray(p, dtype=float), g.j, g.w1, g.dt, g.r, g.t_f, pb.x0, pb.v0,
            pb.m0, GRAVITY_MPS2, EXHAUST_VELOCITY_MPS, KN, floor_every, PHI_SERIES,
        )  # fmt: skip
        cc, lbx, ubx = c, lb, ub
        if envelope is not None:
            # elastic: a slack per row at `elastic_kg_per_mps`, so that a plan outside the
            # envelope (the free-t_f optimum, a state the disturbance pushed out) moves in
            rows, lower = _envelope_rows(pb, g, p, envelope, pb.fly(p, g))
            k = len(lower)
            a_eq = np.concatenate([a_eq, rows])
            a_eq = np.concatenate([a_eq, np.zeros((len(a_eq), k))], axis=1)
            a_eq[-k:, -k:] = np.eye(k)
            row_hi = np.concatenate([row_hi, np.full(k, np.inf)])
            rhs = np.concatenate([rhs, lower])
            cc = np.concatenate([c, np.full(k, envelope.elastic_kg_per_mps)])
            lbx = np.concatenate([lbx, np.zeros(k)])
            ubx = np.concatenate([ubx, np.full(k, np.inf)])
        x = solve_lp(cc, a_eq, rhs, lbx, ubx, highs, row_hi)
        if x is None:
            return None
        xs = x[: 6 * n].reshape(3, 2, n)
        p_new = (xs[:, 0] - xs[:, 1]).T * KN
        change = np.abs(p_new - p).max()
        p = p_new
        if change < 1e-1:
            break
    return p


def envelope_fuel_plan(
    pb: Problem,
    p: np.ndarray,
    t_f: float,
    envelope: BrakeEnvelope,
    highs: highspy.Highs | None = None,
    floor_every: int = 0,
    step_s: float = 0.5,
    max_extra_s: float = 15.0,
    passes: int = 8,
) -> tuple[np.ndarray, float] | None:
    """(control points, t_f) of the cheapest plan inside `envelope` found by LP passes
    (`fuel_lp_plan`) at t_f, t_f + step_s, ... (each warm-started from the last feasible plan,
    a homotopy in t_f), stopping two steps after the fuel stops falling; None if none up to
    t_f + max_extra_s. The free-t_f fuel optimum at the same limits is the natural start (a plan
    inside the envelope brakes earlier, so it needs more time, never less). A local optimum:
    an upper bound on the envelope's fuel floor."""
    best: tuple[np.ndarray, float] | None = None
    best_fuel, worse = math.inf, 0
    start = p
    for k in range(int(max_extra_s / step_s) + 1):
        t = t_f + k * step_s
        g = pb.grid(t)
        q = fuel_lp_plan(pb, g, start, passes, highs, floor_every, envelope)
        if q is None:
            if best is not None:
                worse += 1
            if worse >= 2:
                break
            continue
        fl = pb.fly(q, g)
        start = q
        if np.abs(fl.xf).max() > 0.5 or np.abs(fl.vf).max() > 0.1:
            continue  # the LP passes did not converge onto the target
        if envelope_excess(pb, g, q, envelope) > 0.05:
            continue  # not inside yet: the next t_f starts from here
        if fl.fuel < best_fuel:
            best, best_fuel, worse = (q, t), fl.fuel, 0
        else:
            worse += 1
            if worse >= 2:
                break
    return best


def fuel_lp_at(t_f: float, pb: Problem, st: WarmStart, passes: int) -> TfEval:
    """(fuel kg, nan, p) at fixed t_f: `fuel_lp_plan` from `st` (updated in place)."""
    g = pb.grid(t_f)
    p = fuel_lp_plan(pb, g, st.p, passes)
    if p is None:
        return INFEASIBLE
    st.p = p
    st.evals += 1
    return pb.fly(p, g).fuel, math.nan, p


def _fuel_lp_step(
    pb: Problem, p: np.ndarray, g: Grid, delta_kn: float
) -> tuple[np.ndarray, float] | None:
    """One elastic LP of the SLP at control points p (N, 3) N within a box of delta_kn kN.

    Returns (p' (N, 3) N, predicted l1-merit reduction), None if HiGHS fails.
    """
    n = p.shape[0]
    wsum = fuel_weights(g)
    jp = pb.gradients(p, g, sign=1.0)
    jm = pb.gradients(p, g, sign=-1.0)
    a_plus = jp.dc_dp.transpose(0, 2, 1) * KN  # (6, 3, N) per kN
    a_minus = -jm.dc_dp.transpose(0, 2, 1) * KN
    cur = p.T / KN
    pos, neg = np.maximum(cur, 0.0), np.maximum(-cur, 0.0)
    rhs = np.einsum("oan,an->o", a_plus, pos) + np.einsum("oan,an->o", a_minus, neg) - jp.c
    # columns: [T+ axis 0, T- axis 0, T+ axis 1, ...] (6N), then slacks s+ (6), s- (6)
    a_thr = np.stack([a_plus, a_minus], axis=2).reshape(6, 6 * n)
    eye = np.eye(6)
    a_eq = np.concatenate([a_thr, eye, -eye], axis=1)
    cost = np.concatenate([np.tile(wsum, 6) * KN, _MERIT_MU, _MERIT_MU])
    lim = pb.limits
    hi_pm = np.stack([np.maximum(lim.hi, 0.0), np.maximum(-lim.lo, 0.0)], 1) / KN
    cur_pm = np.stack([pos, neg], axis=1)  # (3, 2, N)
    lb = np.maximum(cur_pm - delta_kn, 0.0).reshape(-1)
    ub = np.minimum(cur_pm + delta_kn, hi_pm[:, :, None]).reshape(-1)
    lb = np.minimum(lb, ub)
    x = solve_lp(
        cost,
        a_eq,
        rhs,
        np.concatenate([lb, np.zeros(12)]),
        np.concatenate([ub, np.full(12, np.inf)]),
    )
    if x is None:
        return None
    xs = x[: 6 * n].reshape(3, 2, n)
    p_new = (xs[:, 0] - xs[:, 1]).T * KN
    lin_now = float(np.tile(wsum, 6) @ cur_pm.reshape(-1)) * KN + _MERIT_MU @ np.abs(jp.c)
    return p_new, lin_now - float(cost @ x)


def _merit(fl: Flight) -> float:
    return fl.fuel + float(_MERIT_MU @ np.abs(np.concatenate([fl.xf, fl.vf])))


def fuel_slp(
    pb: Problem,
    p: np.ndarray,
    g: Grid,
    max_iter: int = SLP_MAX_ITER,
    delta_kn: float = 4.0,
    tol_kg: float = 1e-6,
    deadline: float = math.inf,
) -> np.ndarray | None:
    """Trust-region SLP on fuel at fixed t_f from p (N, 3) N; the best control points found."""
    merit = _merit(pb.fly(p, g))
    for _ in range(max_iter):
        if time.perf_counter() > deadline:
            raise SolveTimeout
        step = _fuel_lp_step(pb, p, g, delta_kn)
        if step is None:
            return None
        p_new, pred = step
        merit_new = _merit(pb.fly(p_new, g))
        actual = merit - merit_new
        if pred <= tol_kg * max(merit, 1.0):
            break  # the linearised merit cannot improve: a KKT point of the l1 problem
        if actual >= 0.1 * pred:
            moved = np.abs(p_new - p).max() / KN
            p, merit = p_new, merit_new
            if actual >= 0.75 * pred and moved >= 0.99 * delta_kn:
                delta_kn = min(2.0 * delta_kn, 24.0)
        else:
            delta_kn *= 0.25
            if delta_kn < 1e-6:
                break
    return p


def tf_brent(f: Callable[[float], TfEval], tf0: float, tol_s: float) -> float | None:
    """t_f minimising the fuel LP value by Brent's bounded method on [tf0 / 2, 2 tf0];
    infeasible t_f (too short) get a penalty that falls with t_f so the search walks out."""

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


def solve_fuel(
    pb: Problem,
    deadline: float = math.inf,
    passes: int = 2,
    final_passes: int = 8,
    tf_tol_s: float = 2e-3,
) -> SolverOutput:
    """Free-final-time fuel optimum: `tf_brent` over `fuel_lp_at`, then `fuel_slp` at t_f."""
    return free_final_time(
        pb,
        fuel_lp_at,
        lambda f, tf0: tf_brent(f, tf0, tf_tol_s * 5),
        deadline,
        passes,
        final_passes,
        polish=lambda p, t_f: fuel_slp(pb, p, pb.grid(t_f), deadline=deadline),
    )
