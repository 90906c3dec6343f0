"""One decision's compiled stages (`pd_core.runtime.layer.Runtime.step_rows`): everything before
the actor in one call (`before_actor`), everything after it in one call (`after_actor`), and the
network's inputs in one call (`network_inputs`); see `pd_core.runtime.kernels` for the
conventions.

They call the kernels the stages' own modules call, in the same order (`states_valid`,
`predict_rows`, `thrust_scale_rows`; `handover_row`, `rules_rows`, the pipeline shift of
`record_rows`), so a decision is the same to the bit; what they save is the Python between
those kernels (a few dozen small numpy calls and argument conversions a step).

Memory and settings arrive grouped as the named tuples of `pd_core.runtime.kernels_state`. The
two kernels called on every decision (`before_actor`, `after_actor`) take each group as the named
tuple or as a plain tuple of its fields in order, and name it again first thing (free in compiled
code): numba fingerprints a named tuple's class and field names on every call (about 0.6 us a
group, 3 us a decision), a plain tuple only its elements, so their callers hand them plain
tuples built once (`LatencyCompensator.predict_scaled`, `pipeline`).
"""

from __future__ import annotations

import numpy as np

from pd_core.runtime.kernels import njit, states_valid
from pd_core.runtime.kernels_latency import predict_rows, record_rows, thrust_scale_rows
from pd_core.runtime.kernels_rules import handover_row, rules_rows
from pd_core.runtime.kernels_state import (
    LatencyMemory,
    LatencySettings,
    NavMemory,
    NavModel,
    Pipeline,
    RuleSettings,
)

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
    memory: LatencyMemory,
    settings: LatencySettings,
    nav_memory: NavMemory,
    nav_model: NavModel,
) -> int:
    """`LatencyCompensator.predict_scaled` of rows (B,) observed in obs (B, 7), on the
    compensator's memory and settings and its navigation filter's (each the named tuple or a
    plain tuple of its fields, module docstring): INVALID (nothing done) unless every state
    passes `states_valid` (limits: `pd_core.state.STATE_LIMITS`); JUMPED as `predict_rows`
    returns False (rows marked in jumped (B,), nothing else done); else VALID with the states
    to decide on in out (B, 7) and the vertical thrust scale in scale (B,) (`thrust_scale_rows`
    at `settings.shortfall_sd`, 1 unless `settings.measures_thrust`)."""
    memory, settings = LatencyMemory(*memory), LatencySettings(*settings)
    nav_memory, nav_model = NavMemory(*nav_memory), NavModel(*nav_model)
    if not states_valid(obs, limits):
        return INVALID
    if not predict_rows(rows, obs, out, jumped, memory, settings, nav_memory, nav_model):
        return JUMPED
    if settings.measures_thrust:
        scale[:] = thrust_scale_rows(rows, memory, settings, settings.shortfall_sd)
    else:
        scale[:] = 1.0
    return VALID


@njit(cache=True)
def after_actor(
    proposed: np.ndarray,
    states: np.ndarray,
    scale: np.ndarray,
    rows: np.ndarray,
    rules: RuleSettings,
    pipeline: Pipeline,
    handed_over: bool,
    actions: np.ndarray,
    hand: np.ndarray,
    source: np.ndarray,
    frac: np.ndarray,
    limit: np.ndarray,
    delay: np.ndarray,
    nav: np.ndarray,
) -> bool:
    """`pd_core.runtime.rules.decide` under `rules` and `LatencyCompensator.record` into
    `pipeline` (each the named tuple or a plain tuple of its fields, module docstring) of the
    actions proposed (B,) on the states decided on (B, 7) of rows (B,), counting on the
    vertical thrust scale (B,) where `pipeline.recorded`.

    Unless handed_over: actions = proposed and hand (B,) = `handover_row` (rules on); if any
    row is handed over, returns False there (the caller puts the fallback's actions into
    `actions` where `hand` and calls again with handed_over). Then `rules_rows` (actions,
    source, frac, limit (B,) in place) and, with memory, the commands flown enter the pipeline
    (`pipeline.issued`) and each row's identified delay and navigation-filter state go to
    delay, nav (B,) (0 and False without)."""
    rules, pipeline = RuleSettings(*rules), Pipeline(*pipeline)
    table_n, hi, rp = rules.table_n, rules.hi, rules.params
    has_scale = has_memory = pipeline.recorded
    issued, delay_memory, engaged_memory = pipeline.issued, pipeline.delay, pipeline.engaged
    has_nav = pipeline.nav
    n = len(proposed)
    if not handed_over:
        any_hand = False
        for b in range(n):
            actions[b] = proposed[b]
            hand[b] = rp[0] > 0.0 and handover_row(states[b], hi, rp)
            any_hand = any_hand or hand[b]
        if any_hand:
            return False
    rules_rows(actions, proposed, hand, states, scale, has_scale, rules, source, frac, limit)
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
