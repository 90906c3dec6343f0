"""One decision's compiled stages (`pd_core.runtime.layer.Runtime.step_rows`): everything before
the actor in one call (`before_actor`), everything after it in one call (`after_actor`), and the
network's inputs in one call (`network_inputs`); see `pd_core.runtime.kernels` for the
conventions.

They call the kernels the stages' own modules call, in the same order (`states_valid`,
`predict_rows`, `thrust_scale_rows`; `handover_row`, `rules_rows`, the pipeline shift of
`record_rows`), so a decision is the same to the bit; what they save is the Python between
those kernels (a few dozen small numpy calls and argument conversions a step).
"""

from __future__ import annotations

import numpy as np

from pd_core.runtime.kernels import njit, states_valid
from pd_core.runtime.kernels_latency import predict_rows, record_rows, thrust_scale_rows
from pd_core.runtime.kernels_rules import handover_row, rules_rows

VALID, INVALID, JUMPED = 0, 1, 2
"""what `before_actor` returns"""


@njit(cache=True)
def before_actor(
    obs: np.ndarray,
    limits: np.ndarray,
    rows: np.ndarray,
    out: np.ndarray,
    jumped: np.ndarray,
    scale: np.ndarray,
    want_scale: bool,
    n_sd: float,
    min_evidence: float,
    noise2: float,
    unmeasured: float,
    measured_sd: float,
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
) -> int:
    """`LatencyCompensator.predict_scaled` of rows (B,) observed in obs (B, 7): INVALID (nothing
    done) unless every state passes `states_valid`; JUMPED as `predict_rows` returns False
    (rows marked in jumped (B,), nothing else done); else VALID with the states to decide on in
    out (B, 7) and the vertical thrust scale in scale (B,) (`thrust_scale_rows`, 1 unless
    want_scale)."""
    if not states_valid(obs, limits):
        return INVALID
    if not predict_rows(
        rows, obs, out, jumped, issued, last, score, delay, gain, cov, force_var, win, win_steps,
        win_sums, p, has_nav, nx, ncov, z1, z2, a1, d2_sq, nsteps, noise_var, engaged, nav_p, f,
        bvec, q, p0, c,
    ):  # fmt: skip
        return JUMPED
    if want_scale:
        scale[:] = thrust_scale_rows(
            rows, delay, gain, cov, win_sums, n_sd, min_evidence, noise2, unmeasured, measured_sd
        )
    else:
        scale[:] = 1.0
    return VALID


@njit(cache=True)
def after_actor(
    proposed: np.ndarray,
    states: np.ndarray,
    scale: np.ndarray,
    has_scale: bool,
    handed_over: bool,
    actions: np.ndarray,
    hand: np.ndarray,
    source: np.ndarray,
    frac: np.ndarray,
    limit: np.ndarray,
    level_table: np.ndarray,
    table_n: np.ndarray,
    n_per_axis: np.ndarray,
    hi: np.ndarray,
    rp: np.ndarray,
    has_memory: bool,
    rows: np.ndarray,
    issued: np.ndarray,
    delay_memory: np.ndarray,
    engaged_memory: np.ndarray,
    has_nav: bool,
    delay: np.ndarray,
    nav: np.ndarray,
) -> bool:
    """`pd_core.runtime.rules.decide` and `LatencyCompensator.record` of the actions proposed
    (B,) on the states decided on (B, 7) of rows (B,).

    Unless handed_over: actions = proposed and hand (B,) = `handover_row` (rules on); if any
    row is handed over, returns False there (the caller puts the fallback's actions into
    `actions` where `hand` and calls again with handed_over). Then `rules_rows` (actions,
    source, frac, limit in place) and, with memory, the commands flown enter the pipeline (`issued`)
    and each row's identified delay and navigation-filter state go to delay, nav (B,)."""
    n = len(proposed)
    if not handed_over:
        any_hand = False
        for b in range(n):
            actions[b] = proposed[b]
            hand[b] = rp[0] > 0.0 and handover_row(states[b], hi, rp)
            any_hand = any_hand or hand[b]
        if any_hand:
            return False
    rules_rows(
        actions, proposed, hand, states, scale, has_scale, level_table, table_n, n_per_axis, hi,
        rp, source, frac, limit,
    )  # fmt: skip
    if has_memory:
        thrust = np.empty((n, 3))
        for b in range(n):
            for i in range(3):
                thrust[b, i] = table_n[actions[b], i]
        record_rows(issued, rows, thrust)
    for b in range(n):
        delay[b] = delay_memory[rows[b]] if has_memory else 0
        nav[b] = has_memory and has_nav and engaged_memory[rows[b]]
    return True


@njit(cache=True)
def network_inputs(
    states: np.ndarray,
    limits: np.ndarray,
    scale: np.ndarray,
    near_gain: np.ndarray,
    scaled: np.ndarray,
    near: np.ndarray,
) -> bool:
    """`NumpyQNetwork`'s inputs of states (B, 7): False (nothing done) unless every state
    passes `states_valid`; else states * scale (Eqs. 20-21) into scaled (B, 7) and, for the
    near-pad features (`pd_core.state.near_pad_features`), their first len(near_gain) entries
    times near_gain into near (B, k), for numpy's tanh."""
    if not states_valid(states, limits):
        return False
    k = len(near_gain)
    for b in range(states.shape[0]):
        for i in range(7):
            scaled[b, i] = states[b, i] * scale[i]
        for i in range(k):
            near[b, i] = scaled[b, i] * near_gain[i]
    return True
