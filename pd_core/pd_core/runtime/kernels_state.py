"""What the runtime layer's compiled kernels take, grouped: named tuples of arrays and scalars.

Numba passes a `typing.NamedTuple` to a compiled function as one argument and reads its fields
by name inside it. Each tuple is built once by the stage that owns the arrays and handed to every
call (the arrays are the memory itself, not copies: a kernel writes into them):

- `LatencyMemory`, `LatencySettings`: `pd_core.runtime.latency.LatencyCompensator` (the memory
  tuple again after `reset` or `grow` replace its arrays);
- `NavMemory`, `NavModel`: `pd_core.runtime.navfilter.NavFilter` (the compensator's filter, or
  a filter of no rows where there is none);
- `Pipeline`: the compensator's memory as `kernels_step.after_actor` records into and reads it
  (`NO_PIPELINE` where there is no memory);
- `RuleSettings`: `pd_core.runtime.rules.rule_settings`, once per `Runtime`.

The two kernels of every decision (`kernels_step.before_actor`, `after_actor`) are handed their
groups as plain tuples of these fields, in order (cheaper for numba to dispatch; they name them
again).

Row arrays have one row per lander (`pd_core.runtime.rowmemory.RowMemory`): R rows, L = max
delay + 1 lags. Floats are float64, counts int64. A cached kernel reads a field by its position:
this module's name starts with `kernels` so that an edit of it drops the kernels' cache index
(`pd_core.runtime.kernels`, `drop_stale_cache`) and the next process compiles them again.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class LatencyMemory(NamedTuple):
    """The latency compensator's memory of each row (`LatencyCompensator._fresh`)."""

    issued: np.ndarray
    """(R, L, 3) N: [:, k], the command issued k + 1 steps ago"""
    last: np.ndarray
    """(R, 7) the last observed state (NaN: none yet)"""
    score: np.ndarray
    """(R, L) each lag's forgetting sum of squared velocity residuals, (m/s)^2"""
    delay: np.ndarray
    """(R,) int64 the lag each row is predicted with, steps"""
    gain: np.ndarray
    """(R, L, 3, 3) each lag's thrust matrix (delivered force = gain @ command)"""
    cov: np.ndarray
    """(R, L, 3, 3) the covariance of each lag's thrust matrix rows (one, shared by the rows)"""
    force_var: np.ndarray
    """(R, L) running mean square of each lag's force residual per axis, N^2"""
    win: np.ndarray
    """(R, 2) the window in progress: commanded and observed vertical velocity change, m/s"""
    win_steps: np.ndarray
    """(R,) int64 steps in the window in progress"""
    win_sums: np.ndarray
    """(R, 4) forgetting sums over finished windows: sxx, sxy, syy ((m/s)^2), count"""


class LatencySettings(NamedTuple):
    """A `LatencyConfig` as the latency kernels take it (fixed for a compensator)."""

    params: np.ndarray
    """(7,) [max_delay_steps, thrust_model (0/1), forget per step, switch margin m/s^2, jump m,
    window_steps, window_forget]"""
    nav: bool
    """the prediction starts from the navigation filter's estimate (else the observation)"""
    measures_thrust: bool
    """a vertical thrust scale is identified (max_delay_steps > 0 and thrust_model; else 1)"""
    shortfall_sd: float
    """standard deviations added to the identified vertical gain"""
    window_min_evidence: float
    """the window bound's least sxx, (m/s)^2 (less: no bound)"""
    window_noise2: float
    """2 window_noise^2, (m/s)^2"""
    unmeasured_thrust: float
    """the most the rules count on until the engine is measured (fraction of nominal)"""
    measured_gain_sd: float
    """the gain's standard deviation below which the engine counts as measured"""
    dynamics: np.ndarray
    """the nominal dynamics (`pd_core.runtime.kernels.consts`)"""


class NavMemory(NamedTuple):
    """The navigation filter's memory of each row (`NavFilter._fresh`)."""

    x: np.ndarray
    """(R, 3, 3) each axis' [position m, velocity m/s, acceleration m/s^2] (NaN: none yet)"""
    cov: np.ndarray
    """(R, 3, 3, 3) each axis' covariance"""
    z1: np.ndarray
    """(R, 3, 2) the last [position, velocity] measured on each axis"""
    z2: np.ndarray
    """(R, 3, 2) the one before"""
    a1: np.ndarray
    """(R, 3) the known acceleration of the step before last, m/s^2"""
    d2_sq: np.ndarray
    """(R, 2) running mean square of the second differences (position, velocity)"""
    steps: np.ndarray
    """(R,) int64 observations learnt from"""
    noise_var: np.ndarray
    """(R, 2) the measurement noise variances each row sees, m^2 and (m/s)^2"""
    engaged: np.ndarray
    """(R,) bool rows flying the estimate (else the observation)"""


class NavModel(NamedTuple):
    """A `NavFilterConfig` as the navigation kernels take it (fixed for a filter)."""

    params: np.ndarray
    """(6,) [warm_steps, forget per step, position floor m^2, velocity floor (m/s)^2, position
    prior m^2, velocity prior (m/s)^2]"""
    f: np.ndarray
    """(3, 3) one axis' transition over a step (`navfilter.transition`)"""
    bvec: np.ndarray
    """(3,) its input of a known acceleration"""
    q: np.ndarray
    """(3, 3) process noise"""
    p0: np.ndarray
    """(3, 3) a row's first covariance"""
    dynamics: np.ndarray
    """the nominal dynamics (`pd_core.runtime.kernels.consts`)"""


class Pipeline(NamedTuple):
    """The compensator's memory as `kernels_step.after_actor` records into and reads it (the
    arrays of its `LatencyMemory` and `NavMemory`, not copies)."""

    recorded: bool
    """there is memory (False: `NO_PIPELINE`, nothing recorded or read, the scale ignored)"""
    issued: np.ndarray
    """(R, L, 3) `LatencyMemory.issued`"""
    delay: np.ndarray
    """(R,) int64 `LatencyMemory.delay`"""
    engaged: np.ndarray
    """(R,) bool `NavMemory.engaged` (no rows where there is no filter)"""
    nav: bool
    """there is a navigation filter"""


NO_PIPELINE = tuple(
    Pipeline(
        recorded=False,
        issued=np.zeros((0, 1, 3)),
        delay=np.zeros(0, dtype=np.int64),
        engaged=np.zeros(0, dtype=bool),
        nav=False,
    )
)
"""the `Pipeline` fields where there is no memory, as a plain tuple (as
`LatencyCompensator.pipeline` hands them to `kernels_step.after_actor`)"""


class RuleSettings(NamedTuple):
    """A `RulesConfig`, an action space and a fallback as the rule kernels take them (built once
    by `pd_core.runtime.rules.rule_settings`)."""

    params: np.ndarray
    """(18,) floats: see `pd_core.runtime.kernels_rules`, rule parameters"""
    level_table: np.ndarray
    """(n, 3) int64 levels of each action"""
    table_n: np.ndarray
    """(n, 3) thrust of each action, N"""
    n_per_axis: np.ndarray
    """(3,) int64"""
    hi: np.ndarray
    """(3,) the largest thrust on each axis, N"""
