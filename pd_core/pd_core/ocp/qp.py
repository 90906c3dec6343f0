"""Fast method, energy objective: frozen-mass QP in the control points, 1-D root search on t_f.

For a fixed t_f and a frozen mass profile the final state is linear in the control points and
the axes decouple, so Eq. 4 becomes, per axis, a strictly convex QP with a tridiagonal Hessian,
2 terminal equalities and box bounds, solved by a primal-dual active-set (semismooth Newton)
method in a handful of batched 82 x 82 solves. The mass profile is refreshed from the solution
in SQP passes that linearise the terminal state with its exact Jacobian (mass sensitivity
included, so a fixed point is a true KKT point of Eq. 4), and t_f is the root of the envelope
derivative dJ*/dt_f. Eq. 4 with the mass-dependent |T| of Eq. 3 is non-convex (burning a little
sideways fuel lightens the lander, which pays when T3 is saturated), so there are several local
optima whose costs differ by up to ~0.5 %; this finds one of them.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.linalg.lapack import dptsv

from pd_core.ocp.guess import initial_guess
from pd_core.ocp.model import KN, TF_MAX_S, TF_MIN_S, Grid, Problem, SolverOutput, SolveTimeout

# A t_f evaluation: (J*, dJ*/dt_f or nan, control points or None when infeasible)
TfEval = tuple[float, float, "np.ndarray | None"]
INFEASIBLE: TfEval = (math.inf, -math.inf, None)
# A lateral thrust of exactly 0 sits on the kink of |T| in Eq. 3: there the energy optimum is a
# saddle and the linearisation, sign(0) = 0, cannot leave it. Guesses start this far off it.
KINK_OFFSET_N = 100.0


@dataclass
class WarmStart:
    """What one solve at fixed t_f hands the next: the linearisation point and the active set."""

    p: np.ndarray  # (N, 3) control points, N
    active: np.ndarray | None = None  # (3, N) in {-1, 0, 1}: at the lower bound, free, upper
    evals: int = 0


def cold_start(pb: Problem) -> tuple[WarmStart, float]:
    """(warm start, t_f guess s) from the constant-thrust guess of Sec. 3.1, off the kink."""
    thr0, tf0 = initial_guess(pb.x0, pb.v0, pb.m0, pb.limits, np.arange(10.0, 150.01, 5.0), 13)
    thr0 = thr0.copy()
    thr0[:2] = np.where(np.abs(thr0[:2]) < KINK_OFFSET_N, KINK_OFFSET_N, thr0[:2])
    return WarmStart(np.tile(thr0, (pb.n_control, 1))), tf0


def tridiag_mul(main: np.ndarray, upper: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Q p for symmetric tridiagonal Q and p (..., N)."""
    out = main * p
    out[..., :-1] += upper * p[..., 1:]
    out[..., 1:] += upper * p[..., :-1]
    return out


def _kkt_solve(
    q_main: np.ndarray,
    q_upper: np.ndarray,
    jac: np.ndarray,
    rhs: np.ndarray,
    act: np.ndarray,
    p_b: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """(p (3, N), lambda (6,)) of the equality-constrained QP with the active bounds fixed at
    p_b: a Schur complement, 3 tridiagonal solves with 7 right-hand sides and one 6 x 6 solve."""
    n = q_main.shape[0]
    jt = jac.transpose(1, 2, 0)  # (3, N, 6)
    free = (act == 0).astype(float)
    r = np.concatenate(
        [(free * tridiag_mul(q_main, q_upper, p_b))[..., None], free[..., None] * jt], -1
    )
    x = np.empty((3, n, 7))
    for ax in range(3):
        f = free[ax]
        # symmetric positive definite tridiagonal (Q on the free points, identity on the fixed
        # ones): LAPACK dptsv, 5x cheaper than scipy's solve_banded (bench/mpc_speed.py)
        _, _, x[ax], info = dptsv(q_main * f + (1.0 - f), q_upper * f[:-1] * f[1:], r[ax])
        if info != 0:
            raise np.linalg.LinAlgError(f"dptsv: info {info}")
    s = 0.5 * np.einsum("oan,anp->op", jac, x[..., 1:])
    lam = np.linalg.solve(s, np.einsum("oan,an->o", jac, p_b - x[..., 0]) - rhs)
    return p_b - x[..., 0] - 0.5 * np.einsum("anp,p->an", x[..., 1:], lam), lam


def pdas_qp(
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
    primal and dual violations; stops when the guess repeats (typically 2-5 solves). Q is given
    by its diagonals (tridiagonal, positive definite), jac (6, 3, N), rhs (6,), lo/hi (3,),
    active0 (3, N) in {-1, 0, 1}. Returns (p (3, N), lambda (6,), active, ok).
    """
    n = q_main.shape[0]
    act = np.zeros((3, n), dtype=np.int8) if active0 is None else active0.copy()
    jt = jac.transpose(1, 2, 0)
    lam = np.zeros(6)
    p = np.zeros((3, n))
    for _ in range(max_iter):
        p_b = np.where(act > 0, hi[:, None], np.where(act < 0, lo[:, None], 0.0))
        try:
            p, lam = _kkt_solve(q_main, q_upper, jac, rhs, act, p_b)
        except (np.linalg.LinAlgError, ValueError):
            return p, lam, act, False
        grad = 2.0 * tridiag_mul(q_main, q_upper, p) + np.einsum("anp,p->an", jt, lam)
        fixed = act != 0
        new = np.zeros_like(act)
        new[(fixed & (act > 0) & (grad < 0)) | (~fixed & (p > hi[:, None]))] = 1
        new[(fixed & (act < 0) & (grad > 0)) | (~fixed & (p < lo[:, None]))] = -1
        if np.array_equal(new, act):
            return p, lam, act, True
        act = new
    return p, lam, act, False


def energy_qp_plan(
    pb: Problem, g: Grid, st: WarmStart, passes: int
) -> tuple[np.ndarray, np.ndarray] | None:
    """(control points (N, 3) N, terminal multipliers (6,)) after up to `passes` SQP passes of
    the PDAS QP from `st` (its active set updated in place) at the fixed t_f of grid g; None if
    a QP fails. The receding-horizon teacher calls this with passes=1."""
    q_main, q_upper = g.hessian_diagonals()
    p, active = st.p, st.active
    lo, hi = pb.limits.lo / KN, pb.limits.hi / KN
    lam = np.zeros(6)
    for _ in range(passes):
        jac, rhs, _ = pb.linearised(p, g)
        pk, lam, active, ok = pdas_qp(q_main, q_upper, jac, rhs, lo, hi, active)
        if not ok:
            return None
        p_new = pk.T * KN
        change = np.abs(p_new - p).max()
        p = p_new
        if change < 1e-2:
            break
    st.active = active
    return p, lam


def energy_at(t_f: float, pb: Problem, st: WarmStart, passes: int) -> TfEval:
    """(J* kN^2 s, dJ*/dt_f, p) at fixed t_f: `energy_qp_plan` from `st` (updated in place);
    the derivative comes from the envelope theorem, dJ*/dt_f = dJ/dt_f + lambda . dc/dt_f at
    the optimum."""
    g = pb.grid(t_f)
    out = energy_qp_plan(pb, g, st, passes)
    if out is None:
        return INFEASIBLE
    p, lam = out
    st.p = p
    st.evals += 1
    gr = pb.gradients(p, g)
    return gr.j / KN**2, gr.dj_dtf / KN**2 + float(lam @ gr.dc_dtf), p


def _bracket_root(f: Callable[[float], TfEval], tf0: float) -> tuple[float, ...] | float | None:
    """(a, da, b, db) with dJ*/dt_f of opposite signs, a bound of the t_f range where the sign
    never changes, or None (nothing feasible): secant steps on the envelope derivative from
    the guess (an infeasible t_f counts as too short)."""
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
    return a, da, b, db


def tf_root(f: Callable[[float], TfEval], tf0: float, tol_s: float) -> float | None:
    """t_f where dJ*/dt_f = 0: bracketed from the guess, then Illinois false position.

    J* is flat at its minimum (J'' ~ J / t_f^2), so tol_s = 0.02 s moves the cost by < 1e-6.
    The stored bracket ends are never re-evaluated: with warm starts a re-evaluation can differ
    in the last digits and flip a sign the bracket relies on.
    """
    br = _bracket_root(f, tf0)
    if br is None or isinstance(br, float):
        return br
    a, da, b, db = br
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


def free_final_time(
    pb: Problem,
    at: Callable[[float, Problem, WarmStart, int], TfEval],
    search: Callable[[Callable[[float], TfEval], float], float | None],
    deadline: float,
    passes: int,
    final_passes: int,
    polish: Callable[[np.ndarray, float], np.ndarray | None] | None = None,
) -> SolverOutput:
    """The free-final-time driver both objectives share: a cold start, a 1-D `search` over t_f of
    the fixed-t_f solve `at` (warm-started, `passes` passes), `final_passes` at the t_f found,
    then an optional `polish(p, t_f)`. Checks the deadline before every fixed-t_f solve."""
    st, tf0 = cold_start(pb)

    def f(t_f: float, n_pass: int = passes) -> TfEval:
        if time.perf_counter() > deadline:
            raise SolveTimeout
        return at(t_f, pb, st, n_pass)

    try:
        t_f = search(f, tf0)
        p = None if t_f is None else f(t_f, final_passes)[2]
        if p is not None and t_f is not None and polish is not None:
            p = polish(p, t_f)
    except SolveTimeout:
        return SolverOutput(st.p, tf0, st.evals, "timed out", False)
    if t_f is None or p is None:
        return SolverOutput(
            st.p, tf0, st.evals, "no feasible thrust schedule in the searched t_f range", False
        )
    return SolverOutput(p, t_f, st.evals, "converged", True)


def solve_energy(
    pb: Problem,
    deadline: float = math.inf,
    passes: int = 2,
    final_passes: int = 8,
    tf_tol_s: float = 2e-3,
) -> SolverOutput:
    """Free-final-time energy optimum: `tf_root` over `energy_at`, then `final_passes` at t_f."""
    return free_final_time(
        pb,
        energy_at,
        lambda f, tf0: tf_root(f, tf0, tf_tol_s),
        deadline,
        passes,
        final_passes,
    )
