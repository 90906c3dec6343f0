"""Compiled latency stage (`pd_core.runtime.latency`): lag scores, thrust-matrix Kalman step,
windows, prediction through the queued commands; one loop over the rows given; see
`pd_core.runtime.kernels` for the conventions."""

from __future__ import annotations

import numpy as np

from pd_core.runtime.kernels import _DT, _G, _dot3, _matvec, njit, step_nominal
from pd_core.runtime.kernels_nav import _nav_row
from pd_core.runtime.kernels_state import LatencyMemory, LatencySettings, NavMemory, NavModel


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
    rows: np.ndarray, memory: LatencyMemory, settings: LatencySettings, n_sd: float
) -> np.ndarray:
    """(B,) vertical thrust scale of rows (B,): the lag's vertical gain + n_sd sd, or the
    window bound where lower, at most `settings.unmeasured_thrust` while that sd is not below
    `settings.measured_gain_sd` (`LatencyCompensator.vertical_thrust_scale`)."""
    delay, gain, cov, win_sums = memory.delay, memory.gain, memory.cov, memory.win_sums
    min_evidence, noise2 = settings.window_min_evidence, settings.window_noise2
    unmeasured, measured_sd = settings.unmeasured_thrust, settings.measured_gain_sd
    out = np.empty(len(rows))
    for b in range(len(rows)):
        r = rows[b]
        lag = delay[r]
        sd = np.sqrt(max(cov[r, lag, 2, 2], 0.0))
        per_step = gain[r, lag, 2, 2] + n_sd * sd
        w = win_sums[r]
        out[b] = min(per_step, window_bound(w[0], w[1], w[2], w[3], n_sd, min_evidence, noise2))
        if unmeasured < 1.0 and not sd < measured_sd:
            out[b] = min(out[b], unmeasured)
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


@njit(cache=True)
def _observe_row(
    r: int,
    dv: np.ndarray,
    mass: float,
    memory: LatencyMemory,
    settings: LatencySettings,
    work: np.ndarray,
) -> None:
    """Row r saw the velocity change dv (3,) over the last step at `mass`: score the lags,
    identify their thrust matrices, move the lag estimate where the evidence says (by the
    switch margin), add the step to the window (into `memory`). work: scratch (>= lags + 12,)."""
    issued, score, delay, gain = memory.issued, memory.score, memory.delay, memory.gain
    cov, force_var, win, win_steps = memory.cov, memory.force_var, memory.win, memory.win_steps
    win_sums, p, c = memory.win_sums, settings.params, settings.dynamics
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
    memory: LatencyMemory,
    settings: LatencySettings,
    nav_memory: NavMemory,
    nav_model: NavModel,
) -> bool:
    """`LatencyCompensator.predict` of rows (B,) observed in states obs (B, 7): the states to
    decide on into out (B, 7), starting from the navigation filter's (nav_memory, nav_model)
    where `settings.nav`. First, rows whose observation is more than the jump distance from
    where they were heading are marked in jumped (B,) and, if any, nothing else is done and
    False is returned (the caller clears them and calls again)."""
    issued, last, delay, gain = memory.issued, memory.last, memory.delay, memory.gain
    p, has_nav, c = settings.params, settings.nav, settings.dynamics
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
            _observe_row(r, dv, last[r, 6], memory, settings, work)
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
            _nav_row(r, o, acc, out[b], nav_memory, nav_model, work)
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
