"""The three rules of the runtime layer, as pure functions (ours; a Simplex-style filter).

On the state decided on (physical [x, y, z, vx, vy, vz, m], SI), in this order:

1. **Handover** (`handover_mask`): the fallback (ZEM/ZEV-vernier, `pd_core.teachers.zemzev`)
   flies instead of the network where its lateral limit binds above `handover_altitude_m`
   (full lateral thrust needs longer to null the sideways motion than the braking profile
   leaves), or where the lander is lighter than `handover_mass_kg` (outside what the network
   learnt).
2. **Brake** (`brake_mask`): full vertical thrust where one step of the commanded vertical thrust
   (counted at `thrust_margin` of what the engine delivers) would leave the lander descending
   faster than the braking limit of `pd_core.envelope` for the force margin * f * T_z,max,

       v_max(z, m) = sqrt(v_land^2 + 2 z (margin * f * T_z,max / m - g))

   at the mass now, or, with `brake_mass_loss`, counting on the mass lost while braking (the
   rocket equation at that force); f is the delivered fraction of vertical thrust measured in
   flight where it is short (`pd_core.runtime.latency`; until the engine is measured, the
   fraction `LatencyConfig.unmeasured_thrust`). A step that ends on the ground is judged by its
   touchdown speed (`touchdown_speed_mps`) instead. The decision records which limit fired.
3. **Guard** (`guard_mask`): below `guard_altitude_m` a descending lander may not free-fall: a
   zero vertical command is raised one level (where that level would climb faster than
   `guard_climb_mps2`, only a descent faster than the land speed counts).

`apply_rules` returns the action flown and who decided it (`pd_core.runtime.decision`).
Settings: `pd_core.runtime.config.RulesConfig`; the evidence behind each number is in
`docs/experiments/runtime-layer-history.md`. The arithmetic, lander by lander, is compiled
(`pd_core.runtime.kernels`: `brake_row`, `guard_row`, `handover_row`, `rules_rows`); the functions
here take arrays of landers.
"""

from __future__ import annotations

import numpy as np

from pd_core.actions import ActionSpace
from pd_core.config import DT_S, GRAVITY_MPS2
from pd_core.runtime import kernels_rules as kernels
from pd_core.runtime.config import RulesConfig
from pd_core.runtime.kernels_state import RuleSettings
from pd_core.teachers.zemzev import ZemZevController, ZemZevParams


def rule_settings(
    p: RulesConfig, space: ActionSpace, fallback: ZemZevParams | None = None
) -> RuleSettings:
    """The kernels' settings of the rules `p` over `space`, with the fallback's braking profile
    `fallback` (its handover condition; default gains where None)."""
    f = fallback or ZemZevParams()
    raised = float(space.levels_to_thrust(np.array([0, 0, 1]))[2])
    params = np.array(
        [
            p.enabled, p.thrust_margin, p.land_speed_mps, p.touchdown_speed_mps,
            p.measured_thrust, p.min_measured_thrust, p.guard_altitude_m, p.guard_climb_mps2,
            p.handover_altitude_m, p.handover_mass_kg, f.brake_accel_mps2, f.brake_margin,
            f.land_speed_mps, f.min_brake_accel_mps2, raised, float(-GRAVITY_MPS2[2]), DT_S,
            p.brake_mass_loss,
        ],
        dtype=float,
    )  # fmt: skip
    return RuleSettings(
        params,
        np.ascontiguousarray(space.level_table, dtype=np.int64),
        np.ascontiguousarray(space.table_n, dtype=float),
        np.asarray(space.n_per_axis, dtype=np.int64),
        np.ascontiguousarray(space.limits.hi, dtype=float),
    )


def _states(states: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(np.atleast_2d(states), dtype=float).reshape(-1, 7)


def max_descent_speed_mps(
    altitude_m: np.ndarray,
    mass_kg: np.ndarray,
    max_vertical_thrust_n: float | np.ndarray,
    p: RulesConfig,
) -> np.ndarray:
    """Fastest descent speed (m/s, >= 0) from which the margin thrust still brakes to the land
    speed by the pad (with the mass lost while braking where `p.brake_mass_loss`); the land
    speed itself where the lander cannot brake at all."""
    args = (np.asarray(v, dtype=float) for v in (altitude_m, mass_kg, max_vertical_thrust_n))
    z, m, t = np.broadcast_arrays(*args)
    rp = rule_settings(p, _ANY_SPACE).params
    flat = (np.ascontiguousarray(v).reshape(-1) for v in (z, m, t))
    out = kernels.max_descent_speeds(*flat, rp)
    return out.reshape(z.shape)


def brake_mask(
    states: np.ndarray,
    vertical_thrust_n: np.ndarray,
    max_vertical_thrust_n: float | np.ndarray,
    p: RulesConfig,
) -> np.ndarray:
    """(B,) True where the states (B, 7), after one step of the commanded vertical thrust (B,)
    at the margin, would descend beyond the braking limit (looking one step ahead: braking at
    the margin thrust once the limit is crossed merely keeps the excess speed); a step that ends
    on the ground is judged by its touchdown speed (where `p.touchdown_speed_mps` > 0)."""
    s = _states(states)
    thrust = np.broadcast_to(np.asarray(vertical_thrust_n, dtype=float), len(s))
    top = np.broadcast_to(np.asarray(max_vertical_thrust_n, dtype=float), len(s))
    rp = rule_settings(p, _ANY_SPACE).params
    return np.array([kernels.brake_row(s[b], thrust[b], top[b], rp) for b in range(len(s))],
                    dtype=bool)  # fmt: skip


def guard_mask(
    states: np.ndarray, vertical_levels: np.ndarray, p: RulesConfig, raised_thrust_n: float
) -> np.ndarray:
    """(B,) True where the states (B, 7) are below the guard altitude, descending, and the
    vertical level (B,) is the lowest (free fall); where the raised level (`raised_thrust_n`, N)
    would climb faster than `p.guard_climb_mps2`, only a descent faster than the land speed
    counts."""
    s = _states(states)
    levels = np.broadcast_to(np.asarray(vertical_levels, dtype=np.int64), len(s))
    rp = rule_settings(p, _ANY_SPACE).params
    return np.array(
        [kernels.guard_row(s[b], levels[b], float(raised_thrust_n), rp) for b in range(len(s))],
        dtype=bool,
    )


def handover_mask(
    states: np.ndarray, max_thrust_n: np.ndarray, p: RulesConfig, fallback: ZemZevController
) -> np.ndarray:
    """(B,) True where the states (B, 7) are above the handover altitude and the fallback's
    lateral limit binds (`lateral_brake_accel_mps2` below its braking deceleration at full
    thrust `max_thrust_n` (3,), N), or lighter than the handover mass."""
    rp = rule_settings(p, _ANY_SPACE, fallback.params).params
    return kernels.handover_rows(_states(states), np.asarray(max_thrust_n, dtype=float), rp)


def decide(
    settings: RuleSettings,
    proposed: np.ndarray,
    states: np.ndarray,
    fallback: ZemZevController,
    vertical_thrust_scale: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """`apply_rules` with its settings built (`rule_settings`), the delivered fraction of the
    commanded vertical thrust the braking limit counted on (n,): the measured
    `vertical_thrust_scale` (n,) where below 1 and `measured_thrust`, floored at
    `min_measured_thrust`; else 1 (a measured surplus is never counted on); and the braking
    limit that fired (n,) uint8 (`pd_core.runtime.decision.LIMITS`)."""
    a = np.array(proposed, dtype=np.int64).reshape(-1)
    s = _states(states)
    rp = settings.params
    n = len(a)
    hand = kernels.handover_rows(s, settings.hi, rp) if rp[0] > 0.0 else np.zeros(n, dtype=bool)
    if hand.any():
        a[hand] = fallback.act_batch(s[hand])
    source = np.empty(n, dtype=np.uint8)
    frac = np.empty(n)
    limit = np.empty(n, dtype=np.uint8)
    has_scale = vertical_thrust_scale is not None
    scale = np.ascontiguousarray(vertical_thrust_scale, dtype=float) if has_scale else frac
    kernels.rules_rows(
        a, np.asarray(proposed, dtype=np.int64).reshape(-1), hand, s, scale, has_scale, settings,
        source, frac, limit,
    )  # fmt: skip
    return a, source, frac, limit


def apply_rules(
    proposed: np.ndarray,
    states: np.ndarray,
    space: ActionSpace,
    p: RulesConfig,
    fallback: ZemZevController,
    vertical_thrust_scale: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(actions flown (B,), source (B,) uint8) for the actions (B,) proposed in states (B, 7):
    the fallback's action where `handover_mask`; then full vertical thrust where `brake_mask`
    (counting on the delivered fraction of the vertical thrust `decide` says), else one
    vertical level up where `guard_mask`. The source is NETWORK where the action flown is the
    proposed one, else the last rule that changed it."""
    settings = rule_settings(p, space, fallback.params)
    return decide(settings, proposed, states, fallback, vertical_thrust_scale)[:2]


_ANY_SPACE = ActionSpace()
"""the masks' settings do not depend on the action space"""
