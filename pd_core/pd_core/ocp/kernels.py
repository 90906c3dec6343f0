"""The fuel LP's per-step arithmetic, compiled (numba): the flight, its exact terminal Jacobian
and the linearised constraint rows of one LP pass.

`pd_core.ocp.model` (`Problem.fly`, `Problem.gradients`, `Grid.wt_mul`) and
`pd_core.ocp.fuel.fuel_lp_plan` call these; each kernel is one loop over the integration steps
doing what their docstrings describe (the closed-form flight, the reverse-mode adjoint through the
mass, the segment sums of W^T, the mass-frozen altitude rows), in the numpy's order of
operations except the sums over steps, which run in step order. One LP pass of the receding-
horizon teacher was about 40 small numpy calls; it is now one call (bench/mpc_speed.py).

Constants arrive as arguments (`phi`: the series PHI1, PHI2 of `pd_core.dynamics` and their
derivatives', highest power first, the derivatives' padded with a leading 0; the exhaust
velocity; gravity): nothing is frozen into the compiled code. `cache=True` keeps the machine code
next to this file; after an edit the first process compiles again (a few seconds).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def _horner(c: np.ndarray, z: float) -> float:
    out = c[0]
    for k in range(1, len(c)):
        out *= z
        out += c[k]
    return out


@njit(cache=True)
def interp(p: np.ndarray, j: np.ndarray, w1: np.ndarray) -> np.ndarray:
    """Step thrusts (n, 3) N: control points p (n_control, 3) interpolated at each step's
    midpoint (left point j, weight w1 of the right one)."""
    n = len(j)
    u = np.empty((n, 3))
    for i in range(n):
        for a in range(3):
            u[i, a] = (1.0 - w1[i]) * p[j[i], a] + w1[i] * p[j[i] + 1, a]
    return u


@njit(cache=True)
def flight(
    u: np.ndarray, dt: np.ndarray, m0: float, c_e: float, phi: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """(m, z, k, h, fuel kg) of step thrusts u (n, 3) N over steps dt (n,) s from mass m0 kg:
    m_i the mass at step i's start, z_i = burn_i / m_i, and the velocity and position gains
    k_i = dt_i phi1(z_i) / m_i, h_i = dt_i^2 phi2(z_i) / m_i of `pd_core.dynamics.step`."""
    n = len(dt)
    m, z, k, h = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    cum = 0.0
    for i in range(n):
        burn = (abs(u[i, 0]) + abs(u[i, 1]) + abs(u[i, 2])) * dt[i] / c_e
        m[i] = m0 - cum
        cum += burn
        z[i] = burn / m[i]
        k[i] = dt[i] / m[i] * _horner(phi[0], z[i])
        h[i] = dt[i] * dt[i] / m[i] * _horner(phi[1], z[i])
    return m, z, k, h, cum


@njit(cache=True)
def final_state(
    u: np.ndarray,
    k: np.ndarray,
    h: np.ndarray,
    r: np.ndarray,
    t_f: float,
    x0: np.ndarray,
    v0: np.ndarray,
    g: np.ndarray,
) -> np.ndarray:
    """[x_f, v_f] (6,) m, m/s: x0 + v0 t_f + g t_f^2 / 2 + sum (k_i r_i + h_i) u_i and
    v0 + g t_f + sum k_i u_i (r_i: time remaining after step i)."""
    c = np.empty(6)
    for a in range(3):
        sx, sv = 0.0, 0.0
        for i in range(len(k)):
            sx += (k[i] * r[i] + h[i]) * u[i, a]
            sv += k[i] * u[i, a]
        c[a] = x0[a] + v0[a] * t_f + 0.5 * g[a] * t_f**2 + sx
        c[3 + a] = v0[a] + g[a] * t_f + sv
    return c


@njit(cache=True)
def wt_mul(j: np.ndarray, w1: np.ndarray, n_control: int, v: np.ndarray) -> np.ndarray:
    """W^T v (n_control, q) for step values v (n, q): the adjoint of `interp`."""
    q = v.shape[1]
    out = np.zeros((n_control, q))
    right = np.zeros((n_control, q))
    for i in range(len(j)):
        for b in range(q):
            out[j[i], b] += (1.0 - w1[i]) * v[i, b]
            right[j[i], b] += w1[i] * v[i, b]
    for kc in range(n_control - 1, 0, -1):
        for b in range(q):
            out[kc, b] += right[kc - 1, b]
    return out


@njit(cache=True)
def terminal_adjoint(
    u: np.ndarray,
    m: np.ndarray,
    z: np.ndarray,
    k: np.ndarray,
    h: np.ndarray,
    dt: np.ndarray,
    r: np.ndarray,
    sign: float,
    c_e: float,
    phi: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(dc/du (n, 6, 3), the t_f derivative through the last step's gains (6,), sign(u) (n, 3),
    mdot (n,)) of c = [x_f, v_f]; `sign` (+-1, or NaN for sign(0) = 0) replaces sign(u) where
    u = 0 (see `Problem.gradients`).

    Reverse mode by hand: each output depends on u_i directly through the gains and indirectly
    through the mass of every later step (m_l = m0 - sum_{j<l} burn_j), a reverse running sum.
    """
    phi1, phi2, dphi1, dphi2 = phi[0], phi[1], phi[2], phi[3]
    n = len(dt)
    du = np.zeros((n, 6, 3))
    sg = np.empty((n, 3))
    mdot = np.empty(n)
    later = np.zeros(6)  # sum over the steps after i of the mass adjoint b
    gk = np.empty(6)
    gh = np.empty(6)
    for i in range(n - 1, -1, -1):
        mdot[i] = (abs(u[i, 0]) + abs(u[i, 1]) + abs(u[i, 2])) / c_e
        p1d = _horner(dphi1, z[i])
        p2d = _horner(dphi2, z[i])
        mm = m[i] * m[i]
        dk_dmdot = dt[i] * dt[i] / mm * p1d
        dh_dmdot = dt[i] ** 3 / mm * p2d
        dk_dm = -(k[i] + dt[i] * p1d * z[i] / m[i]) / m[i]
        dh_dm = -(h[i] + dt[i] * dt[i] * p2d * z[i] / m[i]) / m[i]
        for a in range(3):
            gk[a] = u[i, a] * r[i]  # adjoint of k_i for the outputs x_f (3), v_f (3)
            gk[3 + a] = u[i, a]
            gh[a] = u[i, a]
            gh[3 + a] = 0.0
            s = np.sign(u[i, a])
            sg[i, a] = sign if (u[i, a] == 0.0 and not np.isnan(sign)) else s
        cx = k[i] * r[i] + h[i]
        for o in range(6):
            a_adj = gk[o] * dk_dmdot + gh[o] * dh_dmdot
            b_adj = gk[o] * dk_dm + gh[o] * dh_dm
            scale = (a_adj - dt[i] * later[o]) / c_e
            later[o] += b_adj
            for a in range(3):
                du[i, o, a] = scale * sg[i, a]
        for a in range(3):
            du[i, a, a] += cx
            du[i, 3 + a, a] += k[i]
    # t_f also changes the length of the last step, hence its gains
    last = n - 1
    mm, zz, dtl = m[last], z[last], dt[last]
    p1d = _horner(dphi1, zz)
    p2d = _horner(dphi2, zz)
    dk_ddt = _horner(phi1, zz) / mm + dtl / mm * p1d * mdot[last] / mm
    dh_ddt = 2 * dtl * _horner(phi2, zz) / mm + dtl**2 / mm * p2d * mdot[last] / mm
    dc_dtf = np.empty(6)
    for a in range(3):
        dc_dtf[a] = u[last, a] * r[last] * dk_ddt + u[last, a] * dh_ddt
        dc_dtf[3 + a] = u[last, a] * dk_ddt
    return du, dc_dtf, sg, mdot


@njit(cache=True)
def altitudes(
    u: np.ndarray, k: np.ndarray, h: np.ndarray, dt: np.ndarray, z0: float, vz0: float, gz: float
) -> np.ndarray:
    """Altitude (m) at the end of every step of a flight (vertical gains k, h)."""
    n = len(dt)
    out = np.empty(n)
    vz, z = vz0, z0
    for i in range(n):
        z += dt[i] * vz + 0.5 * gz * dt[i] ** 2 + h[i] * u[i, 2]
        vz += gz * dt[i] + k[i] * u[i, 2]
        out[i] = z
    return out


@njit(cache=True)
def lp_rows(
    p: np.ndarray,
    j: np.ndarray,
    w1: np.ndarray,
    dt: np.ndarray,
    r: np.ndarray,
    t_f: float,
    x0: np.ndarray,
    v0: np.ndarray,
    m0: float,
    g: np.ndarray,
    c_e: float,
    kn: float,
    floor_every: int,
    phi: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rows (6 + m, 6 N) per kN, lower (6 + m,), upper (6 + m,)) of one fuel LP pass at control
    points p (N, 3) N over T = T+ - T- (columns [T+ axis 0, T- axis 0, T+ axis 1, ...]):

    * the terminal state linearised with its exact Jacobian, c(p) + J (p' - p) = 0 (6 rows);
    * with `floor_every` > 0, altitude >= 0 at every floor_every-th step end and the last 10,
      linearised with the mass frozen: dz_i/du_j = h_j + k_j (t_i - t_j) for j <= i (m rows).

    """
    n = p.shape[0]
    u = interp(p, j, w1)
    m, z, k, h, _ = flight(u, dt, m0, c_e, phi)
    c = final_state(u, k, h, r, t_f, x0, v0, g)
    du, _, _, _ = terminal_adjoint(u, m, z, k, h, dt, r, np.nan, c_e, phi)
    n_steps = len(dt)
    sel = np.zeros(n_steps, dtype=np.bool_)
    if floor_every > 0:
        for i in range(floor_every - 1, n_steps, floor_every):
            sel[i] = True
        for i in range(max(n_steps - 10, 0), n_steps):
            sel[i] = True
    n_floor = int(sel.sum())
    rows = np.zeros((6 + n_floor, 6 * n))
    lower = np.empty(6 + n_floor)
    upper = np.empty(6 + n_floor)
    dc_dp = wt_mul(j, w1, n, du.reshape(n_steps, 18))
    for o in range(6):
        acc = 0.0
        for a in range(3):
            for kc in range(n):
                d = dc_dp[kc, 3 * o + a] * kn
                rows[o, 2 * a * n + kc] = d
                rows[o, (2 * a + 1) * n + kc] = -d
                acc += d * (p[kc, a] / kn)
        lower[o] = acc - c[o]
        upper[o] = lower[o]
    if n_floor == 0:
        return rows, lower, upper
    t_end = np.cumsum(dt)
    alt = altitudes(u, k, h, dt, x0[2], v0[2], g[2])
    coef = np.zeros((n_steps, n_floor))
    col = 0
    for s in range(n_steps):
        if not sel[s]:
            continue
        for i in range(s + 1):
            coef[i, col] = h[i] + k[i] * (t_end[s] - t_end[i])
        col += 1
    c_ctrl = wt_mul(j, w1, n, coef)  # (N, m) per N of vertical control point
    col = 0
    for s in range(n_steps):
        if not sel[s]:
            continue
        acc = 0.0
        for kc in range(n):
            d = c_ctrl[kc, col] * kn
            rows[6 + col, 4 * n + kc] = d
            rows[6 + col, 5 * n + kc] = -d
            acc += d * (p[kc, 2] / kn)
        lower[6 + col] = acc - alt[s]
        upper[6 + col] = np.inf
        col += 1
    return rows, lower, upper


def warm_up() -> None:
    """Compile every kernel (or load it from numba's cache) now, on a two-step flight: a
    process that serves solves (the OCP node's solver) pays it at start, not in its first
    request's time limit."""
    p = np.zeros((2, 3))
    j, w1 = np.zeros(2, dtype=np.int64), np.full(2, 0.5)
    dt, r, x = np.full(2, 0.2), np.array([0.2, 0.0]), np.zeros(3)
    phi = np.zeros((4, 9))
    phi[:, -1] = 1.0
    lp_rows(p, j, w1, dt, r, 0.4, x, x, 1000.0, x, 2000.0, 1e3, 1, phi)
    m, z, k, h, _ = flight(p, dt, 1000.0, 2000.0, phi)
    terminal_adjoint(p, m, z, k, h, dt, r, 1.0, 2000.0, phi)
