"""Braking shield: a runtime-assurance filter between a learned policy and the thrusters (ours).

A Q-network is trusted only where it was trained. Under dispersions its worst failures are not
near misses but landers that keep falling at 90-100 m/s until the thrust left can no longer stop
them (a 2200 kg lander with 5 % less thrust has 1.9 m/s^2 of net braking: 2.5 km to stop from
98 m/s). The shield overrides only the vertical thrust, and only when the observed state
would descend faster than the fastest speed from which a fraction `thrust_margin` of full
vertical thrust still brakes to `land_speed_mps` at the pad:

    v_max(z, m) = sqrt(v_land^2 + 2 z (margin * T_z,max / m - g)).

It fires when the policy's own vertical command (counted at the margin) would put the lander
beyond that limit one step later, and then commands full vertical thrust (the horizontal levels
stay the policy's). The two numbers are the ZEM/ZEV teacher's (config.BRAKE_MARGIN,
LAND_SPEED_MPS), not values fitted to a campaign; the teacher applies its margin to the net
braking (0.9 (T/m - g), 2.5 m/s^2 at 2000 kg), the shield to the thrust a shortfall takes away
(0.9 T/m - g, 2.13 m/s^2), so the shield brakes a little earlier than the teacher's profile. A
lander that cannot hover on the margin thrust may descend no faster than the land speed.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from pd_core.actions import ActionSpace
from pd_core.config import BRAKE_MARGIN, DT_S, GRAVITY_MPS2, LAND_SPEED_MPS

_G_MPS2 = float(-GRAVITY_MPS2[2])


@dataclass(frozen=True)
class ShieldParams:
    """Where the shield fires (see the module docstring)."""

    thrust_margin: float = BRAKE_MARGIN
    """fraction of full vertical thrust the braking limit counts on (room for a 5 % thrust
    shortfall, a 2 deg misalignment and 300 N gusts)"""
    land_speed_mps: float = LAND_SPEED_MPS
    """descent speed the limit brakes to at the pad"""

    def __post_init__(self) -> None:
        if not 0.0 < self.thrust_margin <= 1.0:
            raise ValueError(f"shield thrust_margin must be in (0, 1], got {self.thrust_margin}")
        if not 0.0 <= self.land_speed_mps < 2.0:
            raise ValueError(f"shield land_speed_mps must be in [0, 2), got {self.land_speed_mps}")

    def to_dict(self) -> dict[str, float]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ShieldParams:
        unknown = set(d) - {"thrust_margin", "land_speed_mps"}
        if unknown:
            raise ValueError(f"unknown shield setting(s): {', '.join(sorted(unknown))}")
        return cls(**{k: float(v) for k, v in d.items()})


def max_descent_speed_mps(
    altitude_m: np.ndarray, mass_kg: np.ndarray, max_vertical_thrust_n: float, p: ShieldParams
) -> np.ndarray:
    """Fastest descent speed (m/s, >= 0) from which the margin thrust still brakes to the land
    speed by the pad; the land speed itself where the lander cannot brake at all."""
    a_net = p.thrust_margin * max_vertical_thrust_n / np.asarray(mass_kg, dtype=float) - _G_MPS2
    z = np.maximum(np.asarray(altitude_m, dtype=float), 0.0)
    return np.sqrt(p.land_speed_mps**2 + 2.0 * np.maximum(a_net, 0.0) * z)


def shield_mask(
    states: np.ndarray, vertical_thrust_n: np.ndarray, max_vertical_thrust_n: float, p: ShieldParams
) -> np.ndarray:
    """(B,) True where the (observed) physical states (B, 7), after one step of the commanded
    vertical thrust (B,) at the margin, would descend beyond the braking limit. Looking one
    step ahead matters: a shield that fired only once the limit is crossed could never catch
    up, since braking at the margin thrust merely keeps the excess speed."""
    s = np.atleast_2d(states)
    a_z = p.thrust_margin * np.asarray(vertical_thrust_n, dtype=float) / s[:, 6] - _G_MPS2
    vz = s[:, 5] + a_z * DT_S
    z = s[:, 2] + (s[:, 5] + 0.5 * a_z * DT_S) * DT_S
    return -vz > max_descent_speed_mps(z, s[:, 6], max_vertical_thrust_n, p)


def shield_actions(
    actions: np.ndarray, states: np.ndarray, space: ActionSpace, p: ShieldParams
) -> tuple[np.ndarray, np.ndarray]:
    """(actions with full vertical thrust where `shield_mask`, the mask) for actions (B,)
    chosen in physical states (B, 7)."""
    a = np.asarray(actions, dtype=np.int64).reshape(-1)
    fire = shield_mask(states, space.table_n[a, 2], float(space.limits.hi[2]), p)
    if not fire.any():
        return a, fire
    levels = space.level_table[a].copy()
    levels[fire, 2] = space.n_per_axis[2] - 1
    return space.levels_to_action(levels).astype(np.int64), fire
