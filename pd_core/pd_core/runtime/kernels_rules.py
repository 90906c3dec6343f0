"""Compiled rules (`pd_core.runtime.rules`): braking limit, touchdown guard, handover; one loop
over the rows given; see `pd_core.runtime.kernels` for the conventions. The braking law is
`pd_core.envelope`'s (`brake_fires`, `max_descent_speed_for`), compiled in."""

from __future__ import annotations

import numpy as np

from pd_core import envelope
from pd_core.runtime.decision import BRAKE, GUARD, HANDOVER, LIMITS, NETWORK
from pd_core.runtime.kernels import njit
from pd_core.runtime.kernels_state import RuleSettings

# the sources `rules_rows` writes, as numbered in pd_core.runtime.decision
if (NETWORK, BRAKE, GUARD, HANDOVER) != (0, 1, 2, 3):
    raise ImportError("pd_core.runtime.kernels: rules_rows numbers the sources 0, 1, 2, 3")
_LIMITS = (envelope.NO_LIMIT, envelope.DESCENT, envelope.DESCENT_MASS_LOSS, envelope.TOUCHDOWN)
if _LIMITS != tuple(range(len(LIMITS))):
    raise ImportError("pd_core.runtime.decision.LIMITS must number pd_core.envelope's limits")


# ---- rules --------------------------------------------------------------------------------------
# rule parameters (`RuleSettings.params`, `pd_core.runtime.rules.rule_settings`): [enabled,
# thrust_margin, land_speed, touchdown_speed, measured_thrust, min_measured_thrust,
# guard_altitude, guard_climb, handover_altitude, handover_mass, fallback brake_accel, fallback
# brake_margin, fallback land_speed, fallback min_brake_accel, raised vertical thrust N,
# g (m/s^2, > 0), dt s, brake_mass_loss]
_R_ON, _R_MARGIN, _R_LAND, _R_TOUCH, _R_MEAS, _R_MINMEAS, _R_GALT, _R_GCLIMB = range(8)
_R_HALT, _R_HMASS, _R_FBRAKE, _R_FMARGIN, _R_FLAND, _R_FMINBRAKE, _R_RAISED, _R_G, _R_DT = range(
    8, 17
)
_R_MASSLOSS = 17


@njit(cache=True)
def max_descent_speed(z: float, mass: float, max_thrust_z: float, rp: np.ndarray) -> float:
    """`pd_core.runtime.rules.max_descent_speed_mps` of one lander."""
    return envelope.max_descent_speed_for(
        z, mass, rp[_R_MARGIN] * max_thrust_z, rp[_R_LAND], rp[_R_G], rp[_R_MASSLOSS] > 0.0
    )


@njit(cache=True)
def max_descent_speeds(
    z: np.ndarray, mass: np.ndarray, max_thrust_z: np.ndarray, rp: np.ndarray
) -> np.ndarray:
    out = np.empty(len(z))
    for b in range(len(z)):
        out[b] = max_descent_speed(z[b], mass[b], max_thrust_z[b], rp)
    return out


@njit(cache=True)
def brake_limit_row(s: np.ndarray, thrust_z: float, max_thrust_z: float, rp: np.ndarray) -> int:
    """The braking limit a vertical command thrust_z (N, delivered) fires from state s (7,)
    (`pd_core.envelope.brake_fires` at the margin; NO_LIMIT where none)."""
    m = rp[_R_MARGIN]
    return envelope.brake_fires(
        s[2], s[5], s[6], m * thrust_z, m * max_thrust_z, rp[_R_LAND], rp[_R_TOUCH], rp[_R_G],
        rp[_R_DT], rp[_R_MASSLOSS] > 0.0,
    )  # fmt: skip


@njit(cache=True)
def brake_row(s: np.ndarray, thrust_z: float, max_thrust_z: float, rp: np.ndarray) -> bool:
    """`pd_core.runtime.rules.brake_mask` of one state (7,)."""
    return brake_limit_row(s, thrust_z, max_thrust_z, rp) != 0


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
    rules: RuleSettings,
    source: np.ndarray,
    frac: np.ndarray,
    limit: np.ndarray,
) -> None:
    """`pd_core.runtime.rules.apply_rules` after the handover, in place, under `rules`, on the
    states (B, 7) counting on the vertical thrust scale (B,) where has_scale: `actions` (B,) are
    the proposed ones (B,) with the fallback's where `hand` (B,); writes the actions flown into
    `actions`, their source into `source` (B,), the delivered fraction counted on into `frac`
    (B,) and the braking limit that fired (NO_LIMIT where none, or where the rules are off) into
    `limit` (B,)."""
    level_table, table_n, n_per_axis = rules.level_table, rules.table_n, rules.n_per_axis
    hi, rp = rules.hi, rules.params
    top = n_per_axis[2] - 1
    for b in range(len(actions)):
        f = 1.0
        if has_scale and rp[_R_MEAS] > 0.0:
            f = min(max(scale[b], rp[_R_MINMEAS]), 1.0)
        frac[b] = f
        a = actions[b]
        src = 0  # NETWORK
        lim = 0  # NO_LIMIT
        if hand[b] and a != proposed[b]:
            src = 3  # HANDOVER
        if rp[_R_ON] > 0.0:
            s = states[b]
            lz = level_table[a, 2]
            lim = brake_limit_row(s, f * table_n[a, 2], f * hi[2], rp)
            fire = lim != 0
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
        limit[b] = lim
