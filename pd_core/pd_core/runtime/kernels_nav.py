"""Compiled navigation filter (`pd_core.runtime.navfilter`), one loop over the rows given; see
`pd_core.runtime.kernels` for the conventions."""

from __future__ import annotations

import numpy as np

from pd_core.runtime.kernels import _DT, _DT2, _dot3, njit
from pd_core.runtime.kernels_state import NavMemory, NavModel

# ---- navigation filter ------------------------------------------------------------------------
# nav parameters (`NavModel.params`): [warm_steps, forget, floor pos, floor vel, prior pos,
# prior vel]


@njit(cache=True)
def _nav_row(
    r: int,
    obs: np.ndarray,
    acc: np.ndarray,
    out: np.ndarray,
    memory: NavMemory,
    model: NavModel,
    work: np.ndarray,
) -> None:
    """`NavFilter.estimate` of row r: observed state obs (7,), known acceleration acc (3,) m/s^2;
    updates the row's `memory` and writes the state to fly into out (7,) (a copy of obs unless
    the filter is engaged). work: scratch (>= 18,)."""
    x, cov, z1, z2, a1 = memory.x, memory.cov, memory.z1, memory.z2, memory.a1
    d2_sq, steps, noise_var, engaged = memory.d2_sq, memory.steps, memory.noise_var, memory.engaged
    p, f, bvec, q, p0, c = model.params, model.f, model.bvec, model.q, model.p0, model.dynamics
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
    memory: NavMemory,
    model: NavModel,
) -> None:
    """`_nav_row` of each row (B,): observed (B, 7), accelerations (B, 3), into out (B, 7)."""
    work = np.empty(18)
    for b in range(len(rows)):
        _nav_row(rows[b], obs[b], acc[b], out[b], memory, model, work)
