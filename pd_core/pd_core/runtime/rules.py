"""The three rules of the runtime layer, as pure functions (ours; a Simplex-style filter).

On the state decided on (physical [x, y, z, vx, vy, vz, m], SI), in this order:

1. **Handover** (`handover_mask`): the fallback (ZEM/ZEV-vernier, `pd_core.teachers.zemzev`)
   flies instead of the network where its lateral limit binds above `handover_altitude_m`
   (full lateral thrust needs longer to null the sideways motion than the braking profile
   leaves), or where the lander is lighter than `handover_mass_kg` (outside what the network
   learnt).
2. **Brake** (`brake_mask`): full vertical thrust where one step of the commanded vertical thrust
   (counted at `thrust_margin` of what the engine delivers) would leave the lander descending
   faster than the braking limit

       v_max(z, m) = sqrt(v_land^2 + 2 z (margin * f * T_z,max / m - g)),

   f being the delivered fraction of vertical thrust measured in flight where it is short
   (`pd_core.runtime.latency`). A step that ends on the ground is judged by its touchdown speed
   (`touchdown_speed_mps`) instead.
3. **Guard** (`guard_mask`): below `guard_altitude_m` a descending lander may not free-fall: a
   zero vertical command is raised one level (where that level would climb faster than
   `guard_climb_mps2`, only a descent faster than the land speed counts).

`apply_rules` returns the action flown and who decided it (`pd_core.runtime.decision`).
Settings: `pd_core.runtime.config.RulesConfig`; the evidence behind each number is in
`docs/experiments/runtime-layer-history.md`.
"""

from __future__ import annotations

import numpy as np

from pd_core.actions import ActionSpace
from pd_core.config import DT_S, GRAVITY_MPS2
from pd_core.runtime.config import RulesConfig
from pd_core.runtime.decision import BRAKE, GUARD, HANDOVER, NETWORK
from pd_core.teachers.zemzev import (
    ZemZevController,
    braking_accel_mps2,
    lateral_brake_accel_mps2,
)

_G_MPS2 = float(-GRAVITY_MPS2[2])


def max_descent_speed_mps(
    altitude_m: np.ndarray,
    mass_kg: np.ndarray,
    max_vertical_thrust_n: float | np.ndarray,
    p: RulesConfig,
) -> np.ndarray:
    """Fastest descent speed (m/s, >= 0) from which the margin thrust still brakes to the land
    speed by the pad; the land speed itself where the lander cannot brake at all."""
    a_net = p.thrust_margin * max_vertical_thrust_n / np.asarray(mass_kg, dtype=float) - _G_MPS2
    z = np.maximum(np.asarray(altitude_m, dtype=float), 0.0)
    return np.sqrt(p.land_speed_mps**2 + 2.0 * np.maximum(a_net, 0.0) * z)


def brake_mask(
    states: np.ndarray,
    vertical_thrust_n: np.ndarray,
    max_vertical_thrust_n: float | np.ndarray,
    p: RulesConfig,
) -> np.ndarray:
    """(B,) True where the states (B, 7), after one step of the commanded vertical thrust (B,)
    at the margin, would descend beyond the braking limit (looking one step ahead: braking at
    the margin thrust once the limit is crossed merely keeps the excess speed)."""
    s = np.atleast_2d(states)
    a_z = p.thrust_margin * np.asarray(vertical_thrust_n, dtype=float) / s[:, 6] - _G_MPS2
    vz = s[:, 5] + a_z * DT_S
    z = s[:, 2] + (s[:, 5] + 0.5 * a_z * DT_S) * DT_S
    over = -vz > max_descent_speed_mps(z, s[:, 6], max_vertical_thrust_n, p)
    if p.touchdown_speed_mps <= 0.0:
        return over
    touchdown_sq = s[:, 5] ** 2 - 2.0 * a_z * np.maximum(s[:, 2], 0.0)
    return np.where(z <= 0.0, touchdown_sq > p.touchdown_speed_mps**2, over)


def guard_mask(
    states: np.ndarray, vertical_levels: np.ndarray, p: RulesConfig, raised_thrust_n: float
) -> np.ndarray:
    """(B,) True where the states (B, 7) are below the guard altitude, descending, and the
    vertical level (B,) is the lowest (free fall); where the raised level (`raised_thrust_n`, N)
    would climb faster than `p.guard_climb_mps2`, only a descent faster than the land speed
    counts."""
    s = np.atleast_2d(states)
    climbs = raised_thrust_n / s[:, 6] - _G_MPS2 > p.guard_climb_mps2
    slowest = np.where(climbs, p.land_speed_mps, 0.0)
    return (
        (s[:, 2] < p.guard_altitude_m) & (s[:, 5] < -slowest) & (np.asarray(vertical_levels) == 0)
    )


def handover_mask(
    states: np.ndarray, max_thrust_n: np.ndarray, p: RulesConfig, fallback: ZemZevController
) -> np.ndarray:
    """(B,) True where the states (B, 7) are above the handover altitude and the fallback's
    lateral limit binds (`lateral_brake_accel_mps2` below its braking deceleration at full
    thrust `max_thrust_n` (3,), N), or lighter than the handover mass."""
    s = np.atleast_2d(states)
    light = s[:, 6] < p.handover_mass_kg
    if p.handover_altitude_m <= 0.0:
        return light
    params = fallback.params
    a_brake = braking_accel_mps2(s[:, 6], params, float(max_thrust_n[2]))
    binds = lateral_brake_accel_mps2(s, params, max_thrust_n) < a_brake
    return ((s[:, 2] > p.handover_altitude_m) & binds) | light


def delivered_fraction(scale: np.ndarray | None, n: int, p: RulesConfig) -> np.ndarray:
    """(n,) fraction of the commanded vertical thrust the braking limit counts on: the measured
    `scale` (n,) where below 1 and `p.measured_thrust`, floored at `p.min_measured_thrust`;
    else 1 (a measured surplus is never counted on)."""
    if scale is None or not p.measured_thrust:
        return np.ones(n)
    return np.clip(np.asarray(scale, dtype=float), p.min_measured_thrust, 1.0)


def apply_rules(
    proposed: np.ndarray,
    states: np.ndarray,
    space: ActionSpace,
    p: RulesConfig,
    fallback: ZemZevController,
    vertical_thrust_scale: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(actions flown (B,), source (B,) uint8) for the actions (B,) proposed in states (B, 7):
    the fallback's action where `handover_mask`; then full vertical thrust where `brake_mask`,
    else one vertical level up where `guard_mask`. The source is NETWORK where the action flown
    is the proposed one, else the last rule that changed it."""
    a = np.asarray(proposed, dtype=np.int64).reshape(-1)
    source = np.full(len(a), NETWORK, dtype=np.uint8)
    if not p.enabled:
        return a, source
    s = np.reshape(states, (-1, 7))
    hand = handover_mask(s, space.limits.hi, p, fallback)
    if hand.any():
        a = a.copy()
        a[hand] = fallback.act_batch(s[hand])
        source[hand & (a != proposed)] = HANDOVER
    levels = space.level_table[a]
    frac = delivered_fraction(vertical_thrust_scale, len(a), p)
    fire = brake_mask(s, frac * space.table_n[a, 2], frac * float(space.limits.hi[2]), p)
    raised = float(space.levels_to_thrust(np.array([0, 0, 1]))[2])
    guard = guard_mask(s, levels[:, 2], p, raised) & ~fire
    if not (fire.any() or guard.any()):
        return a, source
    top = space.n_per_axis[2] - 1
    source[fire & (levels[:, 2] != top)] = BRAKE
    source[guard] = GUARD
    levels = levels.copy()
    levels[fire, 2] = top
    levels[guard, 2] = 1
    out = space.levels_to_action(levels).astype(np.int64)
    source[out == proposed] = NETWORK
    return out, source
