"""The runtime layer's per-lander arithmetic, compiled (numba): one loop over the rows given.

`pd_core.runtime.latency`, `pd_core.runtime.navfilter` and `pd_core.runtime.rules` keep their
memory and settings in numpy arrays (one row per lander, `RowMemory`) and call these kernels on
them; each kernel does, row by row, the arithmetic those modules document (lag residuals and
scores, the thrust-matrix Kalman step, the window sums, the navigation filter's noise learning and
Kalman step with a closed-form 2x2 inverse, the propagation on the nominal dynamics of
`pd_core.dynamics.step`, the vertical thrust scale, the three rules), in the order of operations
of the numpy it replaced (three-term dot products as numpy's einsum sums them, `_dot3`): the
shipped file flies the same actions to the bit on the `standard` campaign. The handover condition
repeats, for one lander, `braking_accel_mps2` and `lateral_brake_accel_mps2` of
`pd_core.teachers.zemzev`. One decision of one lander costs microseconds instead of ~400 small
numpy calls.

Settings arrive as arrays of floats (`consts()`, and each module's own): nothing from a config
is frozen into the compiled code. `cache=True` keeps the machine code next to this file: a fresh
process imports numba (0.4 s) and loads the kernels (0.15 s; `pd_core.runtime.layer` does, when
the first `Runtime` is built); after an edit of this file the first process compiles them again
(about 10 s).

Numba imports SciPy (a version check; BLAS for `np.dot` and `np.linalg` in compiled code): that
would put SciPy on the flight path. Where SciPy is not loaded already, numba is imported here with
SciPy hidden, so that process's compiled code has no BLAS (no kernel uses it).
"""

from __future__ import annotations

import sys

import numpy as np

from pd_core.config import DRY_MASS_KG, DT_S, G0_MPS2, GRAVITY_MPS2, ISP_S
from pd_core.dynamics import PHI1, PHI2
from pd_core.runtime.decision import BRAKE, GUARD, HANDOVER, NETWORK

if "scipy" in sys.modules:
    from numba import njit
else:  # numba imports SciPy to check its version and to look for BLAS: neither is used here
    sys.modules["scipy"] = None  # type: ignore[assignment]  # "import scipy" fails
    try:
        import numba.np.arraymath  # noqa: F401  (its BLAS check, now rather than at a first call)
        from numba import njit
    finally:
        del sys.modules["scipy"]


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


@njit(cache=True)
def lag_residual(
    dv: np.ndarray, mass: float, issued: np.ndarray, gain: np.ndarray, use_gain: bool, c: np.ndarray
) -> float:
    """Squared norm of the velocity change dv (3,) less the one command `issued` (3,) gives
    through the thrust matrix `gain` (3, 3) (identity unless use_gain) on a lander of `mass`."""
    dt = c[_DT]
    total = 0.0
    for i in range(3):
        if use_gain:
            delivered = _dot3(gain[i, 0], gain[i, 1], gain[i, 2], issued[0], issued[1], issued[2])
        else:
            delivered = issued[i]
        e = dv[i] - (delivered / mass + c[_G + i]) * dt
        total += e * e
    return total


@njit(cache=True)
def lag_residuals_rows(
    dv: np.ndarray,
    mass: np.ndarray,
    issued: np.ndarray,
    gain: np.ndarray,
    use_gain: bool,
    c: np.ndarray,
) -> np.ndarray:
    """(B, L) `lag_residual` of each row (dv (B, 3), mass (B,)) and lag (issued (B, L, 3), gain
    (B, L, 3, 3) where use_gain)."""
    n, lags = issued.shape[0], issued.shape[1]
    out = np.empty((n, lags))
    for b in range(n):
        for d in range(lags):
            g = gain[b, d] if use_gain else gain[0, 0]
            out[b, d] = lag_residual(dv[b], mass[b], issued[b, d], g, use_gain, c)
    return out


@njit(cache=True)
def window_bound(
    sxx: float, sxy: float, syy: float, n: float, n_sd: float, min_evidence: float, noise2: float
) -> float:
    """`pd_core.runtime.latency.window_gain_bound` of one row; noise2 = 2 window_noise^2."""
    if not sxx >= min_evidence:
        return np.inf
    noise_var = (syy + noise2) / (n + 2.0)
    return sxy / sxx + n_sd * np.sqrt(noise_var / sxx)


@njit(cache=True)
def window_bounds(
    sxx: np.ndarray,
    sxy: np.ndarray,
    syy: np.ndarray,
    n: np.ndarray,
    n_sd: float,
    min_evidence: float,
    noise2: float,
) -> np.ndarray:
    out = np.empty(len(sxx))
    for b in range(len(sxx)):
        out[b] = window_bound(sxx[b], sxy[b], syy[b], n[b], n_sd, min_evidence, noise2)
    return out


@njit(cache=True)
def thrust_scale_rows(
    rows: np.ndarray,
    delay: np.ndarray,
    gain: np.ndarray,
    cov: np.ndarray,
    win_sums: np.ndarray,
    n_sd: float,
    min_evidence: float,
    noise2: float,
) -> np.ndarray:
    """(B,) vertical thrust scale of rows (B,): the lag's vertical gain + n_sd sd, or the
    window bound where lower (`LatencyCompensator.vertical_thrust_scale`)."""
    out = np.empty(len(rows))
    for b in range(len(rows)):
        r = rows[b]
        lag = delay[r]
        sd = np.sqrt(max(cov[r, lag, 2, 2], 0.0))
        per_step = gain[r, lag, 2, 2] + n_sd * sd
        w = win_sums[r]
        out[b] = min(per_step, window_bound(w[0], w[1], w[2], w[3], n_sd, min_evidence, noise2))
    return out


@njit(cache=True)
def record_rows(issued: np.ndarray, rows: np.ndarray, thrust: np.ndarray) -> None:
    """Commands thrust (B, 3) just issued for rows (B,): the pipeline shifts by one."""
    lags = issued.shape[1]
    for b in range(len(rows)):
        r = rows[b]
        for k in range(lags - 1, 0, -1):
            for i in range(3):
                issued[r, k, i] = issued[r, k - 1, i]
        for i in range(3):
            issued[r, 0, i] = thrust[b, i]


# ---- navigation filter ------------------------------------------------------------------------
# nav parameters (float array): [warm_steps, forget, floor pos, floor vel, prior pos, prior vel]


@njit(cache=True)
def _nav_row(
    r: int,
    obs: np.ndarray,
    acc: np.ndarray,
    out: np.ndarray,
    x: np.ndarray,
    cov: np.ndarray,
    z1: np.ndarray,
    z2: np.ndarray,
    a1: np.ndarray,
    d2_sq: np.ndarray,
    steps: np.ndarray,
    noise_var: np.ndarray,
    engaged: np.ndarray,
    p: np.ndarray,
    f: np.ndarray,
    bvec: np.ndarray,
    q: np.ndarray,
    p0: np.ndarray,
    c: np.ndarray,
    work: np.ndarray,
) -> None:
    """`NavFilter.estimate` of row r: observed state obs (7,), known acceleration acc (3,);
    writes the state to fly into out (7,) (a copy of obs unless the filter is engaged). work:
    scratch (>= 18,)."""
    for k in range(7):
        out[k] = obs[k]
    if np.isnan(x[r, 0, 0]):  # first observation: the filter starts from it
        for a in range(3):
            x[r, a, 0] = obs[a]
            x[r, a, 1] = obs[3 + a]
            x[r, a, 2] = 0.0
            z1[r, a, 0] = obs[a]
            z1[r, a, 1] = obs[3 + a]
            for i in range(3):
                for j in range(3):
                    cov[r, a, i, j] = p0[i, j]
        return
    n_steps = steps[r] + 1
    steps[r] = n_steps
    dt = c[_DT]
    forget = p[1]
    # noise learning: second differences less what the known accelerations explain
    if n_steps >= 2:
        sq0 = 0.0
        sq1 = 0.0
        for a in range(3):
            dp = obs[a] - 2.0 * z1[r, a, 0] + z2[r, a, 0]
            dp -= 0.5 * (acc[a] + a1[r, a]) * c[_DT2]
            dv = obs[3 + a] - 2.0 * z1[r, a, 1] + z2[r, a, 1]
            dv -= (acc[a] - a1[r, a]) * dt
            sq0 += dp * dp
            sq1 += dv * dv
        nf = float(n_steps - 1)
        d2_sq[r, 0] = forget * d2_sq[r, 0] + (1.0 - forget) * (sq0 / 3.0)
        d2_sq[r, 1] = forget * d2_sq[r, 1] + (1.0 - forget) * (sq1 / 3.0)
        norm = 6.0 * (1.0 - forget**nf)
        noise_var[r, 0] = d2_sq[r, 0] / norm
        noise_var[r, 1] = d2_sq[r, 1] / norm
    for a in range(3):
        z2[r, a, 0] = z1[r, a, 0]
        z2[r, a, 1] = z1[r, a, 1]
        z1[r, a, 0] = obs[a]
        z1[r, a, 1] = obs[3 + a]
        a1[r, a] = acc[a]
    # until enough evidence, the noise is taken as the largest designed for
    warm = n_steps < p[0]
    if warm:
        nv0, nv1 = p[4], p[5]
    else:
        nv0, nv1 = max(noise_var[r, 0], p[2]), max(noise_var[r, 1], p[3])
    xm = work[0:3]
    pm = work[3:12].reshape((3, 3))
    gk = work[12:18].reshape((3, 2))
    for a in range(3):
        xa = x[r, a]
        ca = cov[r, a]
        for i in range(3):
            xm[i] = _dot3(f[i, 0], f[i, 1], f[i, 2], xa[0], xa[1], xa[2]) + acc[a] * bvec[i]
        for i in range(3):
            for m in range(3):
                acc_pm = 0.0
                for j in range(3):
                    for k in range(3):
                        acc_pm += f[i, j] * ca[j, k] * f[m, k]
                pm[i, m] = acc_pm + q[i, m]
        nu0 = obs[a] - xm[0]
        nu1 = obs[3 + a] - xm[1]
        s00, s01, s10, s11 = pm[0, 0] + nv0, pm[0, 1], pm[1, 0], pm[1, 1] + nv1
        det = s00 * s11 - s01 * s10
        i00, i01, i10, i11 = s11 / det, -s01 / det, -s10 / det, s00 / det
        for i in range(3):
            gk[i, 0] = pm[i, 0] * i00 + pm[i, 1] * i10
            gk[i, 1] = pm[i, 0] * i01 + pm[i, 1] * i11
        for i in range(3):
            xa[i] = xm[i] + (gk[i, 0] * nu0 + gk[i, 1] * nu1)
            for m in range(3):
                ca[i, m] = pm[i, m] - (gk[i, 0] * pm[0, m] + gk[i, 1] * pm[1, m])
    on = (not warm) and (noise_var[r, 0] > p[2] or noise_var[r, 1] > p[3])
    engaged[r] = on
    if on:
        for a in range(3):
            out[a] = x[r, a, 0]
            out[3 + a] = x[r, a, 1]


@njit(cache=True)
def nav_estimate_rows(
    rows: np.ndarray,
    obs: np.ndarray,
    acc: np.ndarray,
    out: np.ndarray,
    x: np.ndarray,
    cov: np.ndarray,
    z1: np.ndarray,
    z2: np.ndarray,
    a1: np.ndarray,
    d2_sq: np.ndarray,
    steps: np.ndarray,
    noise_var: np.ndarray,
    engaged: np.ndarray,
    p: np.ndarray,
    f: np.ndarray,
    bvec: np.ndarray,
    q: np.ndarray,
    p0: np.ndarray,
    c: np.ndarray,
) -> None:
    """`_nav_row` of each row (B,): observed (B, 7), accelerations (B, 3), into out (B, 7)."""
    work = np.empty(18)
    for b in range(len(rows)):
        _nav_row(
            rows[b], obs[b], acc[b], out[b], x, cov, z1, z2, a1, d2_sq, steps, noise_var,
            engaged, p, f, bvec, q, p0, c, work,
        )  # fmt: skip


# ---- latency compensation ---------------------------------------------------------------------
# latency parameters (float array): [max_delay_steps, thrust_model, forget, switch margin, jump m,
# window_steps, window_forget]


@njit(cache=True)
def _observe_row(
    r: int,
    dv: np.ndarray,
    mass: float,
    issued: np.ndarray,
    score: np.ndarray,
    delay: np.ndarray,
    gain: np.ndarray,
    cov: np.ndarray,
    force_var: np.ndarray,
    win: np.ndarray,
    win_steps: np.ndarray,
    win_sums: np.ndarray,
    p: np.ndarray,
    c: np.ndarray,
    work: np.ndarray,
) -> None:
    """Row r saw the velocity change dv (3,) over the last step at `mass`: score the lags,
    identify their thrust matrices, move the lag estimate where the evidence says (by the
    switch margin), add the step to the window. work: scratch (>= lags + 12,)."""
    dt = c[_DT]
    lags = issued.shape[1]
    thrust_model = p[1] > 0.0
    forget = p[2]
    res = work[0:lags]
    for d in range(lags):
        res[d] = lag_residual(dv, mass, issued[r, d], gain[r, d], thrust_model, c)
    if thrust_model:
        force = work[lags : lags + 3]
        for i in range(3):
            force[i] = mass * (dv[i] / dt - c[_G + i])
        m_dt2 = (mass / dt) ** 2
        pu = work[lags + 3 : lags + 6]
        k = work[lags + 6 : lags + 9]
        err = work[lags + 9 : lags + 12]
        for d in range(lags):
            var = forget * force_var[r, d] + (1.0 - forget) * res[d] * m_dt2 / 3.0
            force_var[r, d] = var
            u = issued[r, d]
            g = gain[r, d]
            pc = cov[r, d]
            for i in range(3):
                pu[i] = _dot3(pc[i, 0], pc[i, 1], pc[i, 2], u[0], u[1], u[2])
            den = var + _dot3(u[0], u[1], u[2], pu[0], pu[1], pu[2])
            for i in range(3):
                k[i] = pu[i] / den
                err[i] = force[i] - _dot3(g[i, 0], g[i, 1], g[i, 2], u[0], u[1], u[2])
            for i in range(3):
                for j in range(3):
                    g[i, j] = g[i, j] + err[i] * k[j]
                    pc[i, j] = pc[i, j] - k[i] * pu[j]
    best = 0
    for d in range(lags):
        score[r, d] = forget * score[r, d] + res[d]
        if score[r, d] < score[r, best]:
            best = d
    now = delay[r]
    if score[r, best] < score[r, now] - p[3]:
        delay[r] = best
    if not thrust_model:
        return
    # the window: commanded and observed vertical velocity change of the lag flown
    lag = delay[r]
    u = issued[r, lag]
    sideways = gain[r, lag, 2, 0] * u[0] + gain[r, lag, 2, 1] * u[1]
    win[r, 0] += u[2] / mass * dt
    win[r, 1] += dv[2] - (c[_G + 2] + sideways / mass) * dt
    win_steps[r] += 1
    if win_steps[r] < p[5]:
        return
    x, y = win[r, 0], win[r, 1]
    wf = p[6]
    sxx = wf * win_sums[r, 0] + x * x
    sxy = wf * win_sums[r, 1] + x * y
    slope = sxy / max(sxx, 1e-12) if sxx > 0.0 else 1.0
    win_sums[r, 0] = sxx
    win_sums[r, 1] = sxy
    win_sums[r, 2] = wf * win_sums[r, 2] + (y - slope * x) ** 2
    win_sums[r, 3] = wf * win_sums[r, 3] + 1.0
    win[r, 0] = 0.0
    win[r, 1] = 0.0
    win_steps[r] = 0


@njit(cache=True)
def predict_rows(
    rows: np.ndarray,
    obs: np.ndarray,
    out: np.ndarray,
    jumped: np.ndarray,
    issued: np.ndarray,
    last: np.ndarray,
    score: np.ndarray,
    delay: np.ndarray,
    gain: np.ndarray,
    cov: np.ndarray,
    force_var: np.ndarray,
    win: np.ndarray,
    win_steps: np.ndarray,
    win_sums: np.ndarray,
    p: np.ndarray,
    has_nav: bool,
    nx: np.ndarray,
    ncov: np.ndarray,
    z1: np.ndarray,
    z2: np.ndarray,
    a1: np.ndarray,
    d2_sq: np.ndarray,
    nsteps: np.ndarray,
    noise_var: np.ndarray,
    engaged: np.ndarray,
    nav_p: np.ndarray,
    f: np.ndarray,
    bvec: np.ndarray,
    q: np.ndarray,
    p0: np.ndarray,
    c: np.ndarray,
) -> bool:
    """`LatencyCompensator.predict` of rows (B,) observed in states obs (B, 7): the states to
    decide on into out (B, 7). First, rows whose observation is more than the jump distance
    from where they were heading are marked in jumped (B,) and, if any, nothing else is done
    and False is returned (the caller clears them and calls again)."""
    dt = c[_DT]
    any_jump = False
    for b in range(len(rows)):
        r = rows[b]
        jumped[b] = False
        if not np.isnan(last[r, 0]):
            sq = 0.0
            for i in range(3):
                e = obs[b, i] - (last[r, i] + last[r, 3 + i] * dt)
                sq += e * e
            if np.sqrt(sq) > p[4]:
                jumped[b] = True
                any_jump = True
    if any_jump:
        return False
    max_delay = int(p[0])
    thrust_model = p[1] > 0.0
    dv = np.empty(3)
    acc = np.empty(3)
    thr = np.empty(3)
    work = np.empty(max(issued.shape[1] + 12, 18))
    for b in range(len(rows)):
        r = rows[b]
        o = obs[b]
        if max_delay > 0 and not np.isnan(last[r, 0]):
            for i in range(3):
                dv[i] = o[3 + i] - last[r, 3 + i]
            _observe_row(
                r, dv, last[r, 6], issued, score, delay, gain, cov, force_var, win, win_steps,
                win_sums, p, c, work,
            )  # fmt: skip
        for i in range(7):
            last[r, i] = o[i]
        lag = delay[r]
        if has_nav:  # the acceleration the lag's command gave over the last step
            u = issued[r, lag]
            if thrust_model:
                _matvec(gain[r, lag], u, thr)
            else:
                thr[:] = u
            for i in range(3):
                acc[i] = thr[i] / o[6] + c[_G + i]
            _nav_row(
                r, o, acc, out[b], nx, ncov, z1, z2, a1, d2_sq, nsteps, noise_var, engaged,
                nav_p, f, bvec, q, p0, c, work,
            )  # fmt: skip
        else:
            out[b, :] = o
        for k in range(lag):  # through the queued commands, oldest first
            u = issued[r, lag - 1 - k]
            if thrust_model:
                _matvec(gain[r, lag], u, thr)
            else:
                thr[:] = u
            step_nominal(out[b], thr, c)
    return True


# the sources `rules_rows` writes, as numbered in pd_core.runtime.decision
if (NETWORK, BRAKE, GUARD, HANDOVER) != (0, 1, 2, 3):
    raise ImportError("pd_core.runtime.kernels: rules_rows numbers the sources 0, 1, 2, 3")


# ---- rules --------------------------------------------------------------------------------------
# rule parameters (float array, `pd_core.runtime.rules.rule_settings`): [enabled, thrust_margin,
# land_speed, touchdown_speed, measured_thrust, min_measured_thrust, guard_altitude, guard_climb,
# handover_altitude, handover_mass, fallback brake_accel, fallback brake_margin, fallback
# land_speed, fallback min_brake_accel, raised vertical thrust N, g (m/s^2, > 0), dt s]
_R_ON, _R_MARGIN, _R_LAND, _R_TOUCH, _R_MEAS, _R_MINMEAS, _R_GALT, _R_GCLIMB = range(8)
_R_HALT, _R_HMASS, _R_FBRAKE, _R_FMARGIN, _R_FLAND, _R_FMINBRAKE, _R_RAISED, _R_G, _R_DT = range(
    8, 17
)


@njit(cache=True)
def max_descent_speed(z: float, mass: float, max_thrust_z: float, rp: np.ndarray) -> float:
    """`pd_core.runtime.rules.max_descent_speed_mps` of one lander."""
    a_net = rp[_R_MARGIN] * max_thrust_z / mass - rp[_R_G]
    return np.sqrt(rp[_R_LAND] ** 2 + 2.0 * max(a_net, 0.0) * max(z, 0.0))


@njit(cache=True)
def max_descent_speeds(
    z: np.ndarray, mass: np.ndarray, max_thrust_z: np.ndarray, rp: np.ndarray
) -> np.ndarray:
    out = np.empty(len(z))
    for b in range(len(z)):
        out[b] = max_descent_speed(z[b], mass[b], max_thrust_z[b], rp)
    return out


@njit(cache=True)
def brake_row(s: np.ndarray, thrust_z: float, max_thrust_z: float, rp: np.ndarray) -> bool:
    """`pd_core.runtime.rules.brake_mask` of one state (7,)."""
    dt = rp[_R_DT]
    a_z = rp[_R_MARGIN] * thrust_z / s[6] - rp[_R_G]
    vz = s[5] + a_z * dt
    z = s[2] + (s[5] + 0.5 * a_z * dt) * dt
    over = -vz > max_descent_speed(z, s[6], max_thrust_z, rp)
    if rp[_R_TOUCH] <= 0.0 or z > 0.0:
        return over
    return s[5] ** 2 - 2.0 * a_z * max(s[2], 0.0) > rp[_R_TOUCH] ** 2


@njit(cache=True)
def guard_row(s: np.ndarray, level_z: int, raised_n: float, rp: np.ndarray) -> bool:
    """`pd_core.runtime.rules.guard_mask` of one state (7,)."""
    slowest = rp[_R_LAND] if raised_n / s[6] - rp[_R_G] > rp[_R_GCLIMB] else 0.0
    return s[2] < rp[_R_GALT] and s[5] < -slowest and level_z == 0


@njit(cache=True)
def _time_to_rest(r: float, v: float, a: float) -> float:
    """`pd_core.teachers.zemzev.min_time_to_rest_s` of one axis."""
    sgn = 1.0 if r + v * abs(v) / (2.0 * a) > 0.0 else -1.0
    return (sgn * v + 2.0 * np.sqrt(max(sgn * a * r + 0.5 * v * v, 0.0))) / a


@njit(cache=True)
def handover_row(s: np.ndarray, hi: np.ndarray, rp: np.ndarray) -> bool:
    """`pd_core.runtime.rules.handover_mask` of one state (7,): the fallback's lateral limit
    binds (`pd_core.teachers.zemzev.lateral_brake_accel_mps2` below `braking_accel_mps2`, for
    one lander) above the handover altitude, or the lander is lighter than the handover mass."""
    m = s[6]
    if m < rp[_R_HMASS]:
        return True
    if rp[_R_HALT] <= 0.0 or not s[2] > rp[_R_HALT]:
        return False
    a_brake = min(rp[_R_FBRAKE], rp[_R_FMARGIN] * (hi[2] / m - rp[_R_G]))
    t_lat = max(_time_to_rest(s[0], s[3], hi[0] / m), _time_to_rest(s[1], s[4], hi[1] / m))
    t = max(t_lat, 1e-6)
    a_lat = max(2.0 * (max(s[2], 0.0) - t * rp[_R_FLAND]) / (t * t), rp[_R_FMINBRAKE])
    return a_lat < a_brake


@njit(cache=True)
def handover_rows(states: np.ndarray, hi: np.ndarray, rp: np.ndarray) -> np.ndarray:
    out = np.empty(len(states), dtype=np.bool_)
    for b in range(len(states)):
        out[b] = handover_row(states[b], hi, rp)
    return out


@njit(cache=True)
def rules_rows(
    actions: np.ndarray,
    proposed: np.ndarray,
    hand: np.ndarray,
    states: np.ndarray,
    scale: np.ndarray,
    has_scale: bool,
    level_table: np.ndarray,
    table_n: np.ndarray,
    n_per_axis: np.ndarray,
    hi: np.ndarray,
    rp: np.ndarray,
    source: np.ndarray,
    frac: np.ndarray,
) -> None:
    """`pd_core.runtime.rules.apply_rules` after the handover, in place: `actions` (B,) are the
    proposed ones with the fallback's where `hand`; writes the actions flown into `actions`,
    their source into `source` (B,) and the delivered fraction counted on into `frac` (B,)."""
    top = n_per_axis[2] - 1
    for b in range(len(actions)):
        f = 1.0
        if has_scale and rp[_R_MEAS] > 0.0:
            f = min(max(scale[b], rp[_R_MINMEAS]), 1.0)
        frac[b] = f
        a = actions[b]
        src = 0  # NETWORK
        if hand[b] and a != proposed[b]:
            src = 3  # HANDOVER
        if rp[_R_ON] > 0.0:
            s = states[b]
            lz = level_table[a, 2]
            fire = brake_row(s, f * table_n[a, 2], f * hi[2], rp)
            guard = not fire and guard_row(s, lz, rp[_R_RAISED], rp)
            if fire or guard:
                if fire:
                    if lz != top:
                        src = 1  # BRAKE
                    lz = top
                else:
                    src = 2  # GUARD
                    lz = 1
                a = (level_table[a, 0] * n_per_axis[1] + level_table[a, 1]) * n_per_axis[2] + lz
                if a == proposed[b]:
                    src = 0
        actions[b] = a
        source[b] = src
