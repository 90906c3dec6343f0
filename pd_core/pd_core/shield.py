"""Braking shield: a runtime-assurance filter between a learned policy and the thrusters (ours).

A Q-network is trusted only where it was trained. Under dispersions its worst failures are not
near misses but landers that keep falling at 90-100 m/s until the thrust left can no longer stop
them (a 2200 kg lander with 5 % less thrust has 1.9 m/s^2 of net braking: 2.5 km to stop from
98 m/s). Its braking limit overrides only the vertical thrust, and only when the observed state
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

A step that ends on the ground is judged by the speed of its touchdown (`touchdown_speed_mps`,
1 m/s: half of Eq. 12's 2 m/s), not by the limit one step below the pad, which is the land speed
(0.5 m/s): a free-falling step from a few centimetres reaches 0.7 m/s, so the limit fired full
thrust there and bounced the lander back up, over and over. Light landers bounced highest
(13 kN lifts a 1300 kg lander at 6 m/s^2), and gusts carried them off the pad meanwhile:
ZEM/ZEV-vernier behind the shield landed 97.0 % of 1500-1700 kg landers under 4x gusts (300
episodes, seed 95000000) and 100 % judged by the touchdown speed; the shipped policy 98.9 ->
99.6 % (1000 episodes), and its nominal flights burn 2 kg less.

The limit counts on the thrust the engine has been measured to deliver (`measured_thrust`):
`pd_core.latency` identifies, for the lag it flies, a thrust matrix from the lander's response,
and where its vertical entry (the delivered fraction of a vertical command: thrust error and
the misalignment's cosine) is below 1, the margin applies to that fraction of the nominal
thrust. A surplus is never counted on, so nominal flights are unchanged. The margin alone
covers a 10 % shortfall only just (0.9 of 13 kN is what an engine 10 % short delivers in all):
under 15 % thrust errors the limit braked too late for the weakest engines and the shipped
policy landed 92.5 % of 200 episodes (touchdowns at up to 12 m/s); on the measured thrust,
100 % (seed 123000000).

Below `guard_altitude_m` (observed) a descending lander may not free-fall either (the touchdown
guard): a zero vertical command is raised one level. Near the pad the limit above cannot help:
one step of free fall adds 0.74 m/s, a step of actuation delay lets two such steps through
before any override lands, and metre-class altitude noise hides how near the pad is. Under the
`all` campaign that is how the shielded student failed (touchdowns at 2.0-2.5 m/s from a slow
hover a few decimetres up). With the paper's three vertical levels the raised one is 6500 N,
the weight of a 1750 kg lander (touchdown masses are 1400-1750 kg): the lander may keep
descending, it only cannot speed up by more than the thrust error and gusts allow. The guard
altitude, 10 m, is five sigma of the largest altitude noise trained on (2 m, `broad`); on a
selection campaign flown before any judged one (`broad`, seed 40000000, 500 episodes, the
three round-9 networks) 5, 10 and 20 m were level (mean 98.59 / 98.58 / 98.60 %, against
97.35 % without the guard and 98.02 % at 2 m), and nominal fuel and miss did not move.
A light lander is the exception: where the raised level climbs faster than 1 m/s^2 (below
1377 kg at 6500 N) the guard turned every zero command of a descending lander into a climb, and
under navigation noise (or with the state made exact by `pd_core.latency`) such landers hovered
above the pad until the episode timed out (a 1600-1800 kg start with 3 m / 0.3 m/s noise: 95.0 %
for the shipped policy, 85.2 % for ZEM/ZEV-vernier behind the shield, seed 81000000). There a
zero command stands while the lander descends slower than the land speed (99.2 % and 99.8 %);
heavier landers keep the strict guard, which 0.3 m/s of velocity noise needs (the relaxed rule
for every mass lost 3 m noise: 98.6 -> 96.8 %; 0.5 m/s^2 measured like 1).

Where the teacher's lateral limit binds above `handover_altitude_m` (observed), the zemzev-vernier
teacher flies instead of the policy (a Simplex fallback: the student is trusted inside the
envelope it was trained in, the law it learned from outside it). The limit is the teacher's own:
full lateral thrust needs longer to null the sideways motion than the braking profile leaves,
so the teacher slows the descent. The student never learned that (the states are rare even under
`broad`): on the wide box it lost 6 of 10 000 episodes from the corners, touching down 1.6-4.8
m/s sideways, where ZEM/ZEV lost none (seed 50000000). With the handover it loses none, and
`box50` of the stress campaign rises from 97.4 to 99.8 % (seed 30000000). Nominal flights do
not reach it above the pad's last metre, where every landing's residual sideways speed makes the
limit bind (the teacher would then fly every touchdown); 5 m is the vernier's altitude, and 2, 10
and 20 m measured the same on the wide box.

The teacher also flies a lander lighter than `handover_mass_kg` (observed), 1350 kg: the
student's lightest training starts (1600 kg, `broad`) touch down at about 1300-1350 kg, so a
lighter lander is outside what it learned. Light landers in gusts were the one place beyond
`standard` where it landed less often than ZEM/ZEV (1450-1650 kg in 5x gusts, held-out
`data/navigation.yaml`: 98.2 % against 100; 1500-1700 kg in 4x gusts, 99.6 against 100). With
the teacher below 1350 kg: 99.4 and 100 %. Nominal flights end at about 1690 kg and never
reach it. 1250 and 1350 kg were compared on the development campaign (seed 95000000: 1450-1650
kg in 5x gusts 97.4 and 99.2 %), and 1350 was kept.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from pd_core.actions import ActionSpace
from pd_core.config import (
    BRAKE_MARGIN,
    DT_S,
    GRAVITY_MPS2,
    GUARD_ALTITUDE_M,
    GUARD_CLIMB_MPS2,
    HANDOVER_ALTITUDE_M,
    HANDOVER_MASS_KG,
    LAND_SPEED_MPS,
    MAX_DELAY_STEPS,
    TOUCHDOWN_SPEED_MPS,
)
from pd_core.controllers import (
    VERNIER_PARAMS,
    ZemZevController,
    braking_accel_mps2,
    lateral_brake_accel_mps2,
)
from pd_core.latency import CompensatesLatency, LatencyCompensator

_G_MPS2 = float(-GRAVITY_MPS2[2])
MIN_MEASURED_THRUST = 0.5
"""floor of the measured thrust fraction the braking limit uses: a guard against a nonsense
estimate, far below the 10-15 % shortfalls the measurement is for"""


@dataclass(frozen=True)
class ShieldParams:
    """Where the shield fires (see the module docstring)."""

    thrust_margin: float = BRAKE_MARGIN
    """fraction of full vertical thrust the braking limit counts on (room for a 5 % thrust
    shortfall, a 2 deg misalignment and 300 N gusts)"""
    land_speed_mps: float = LAND_SPEED_MPS
    """descent speed the limit brakes to at the pad"""
    guard_altitude_m: float = GUARD_ALTITUDE_M
    """below this observed altitude a descending lander may not free-fall (0: no guard)"""
    handover_altitude_m: float = HANDOVER_ALTITUDE_M
    """above this observed altitude the teacher flies where its lateral limit binds (0: never)"""
    handover_mass_kg: float = HANDOVER_MASS_KG
    """below this observed mass the teacher flies: lighter than the student learned to land
    (0: never)"""
    max_delay_steps: float = float(MAX_DELAY_STEPS)
    """longest actuation delay (0.2 s steps) identified in flight and predicted through
    (`pd_core.latency`; 0: decide on the observed state)"""
    nav_filter: float = 1.0
    """1: decide on the state `pd_core.navfilter` estimates where the navigation is noisy;
    0: on the observed state"""
    touchdown_speed_mps: float = TOUCHDOWN_SPEED_MPS
    """a step that ends on the ground fires the braking limit only if the lander would touch
    down faster than this (0: the limit holds below the pad too, as before)"""
    measured_thrust: float = 1.0
    """1: the braking limit counts on the vertical thrust `pd_core.latency` has measured the
    engine to deliver where that is less than nominal; 0: on the nominal thrust"""

    def __post_init__(self) -> None:
        if not 0.0 < self.thrust_margin <= 1.0:
            raise ValueError(f"shield thrust_margin must be in (0, 1], got {self.thrust_margin}")
        if not 0.0 <= self.land_speed_mps < 2.0:
            raise ValueError(f"shield land_speed_mps must be in [0, 2), got {self.land_speed_mps}")
        if not 0.0 <= self.guard_altitude_m <= 1000.0:
            raise ValueError(
                f"shield guard_altitude_m must be in [0, 1000], got {self.guard_altitude_m}"
            )
        if not 0.0 <= self.handover_mass_kg <= 3000.0:
            raise ValueError(
                f"shield handover_mass_kg must be in [0, 3000], got {self.handover_mass_kg}"
            )
        if not 0.0 <= self.handover_altitude_m <= 3000.0:
            raise ValueError(
                f"shield handover_altitude_m must be in [0, 3000], got {self.handover_altitude_m}"
            )
        d = self.max_delay_steps
        if not (0.0 <= d <= 10.0 and d == int(d)):
            raise ValueError(f"shield max_delay_steps must be an integer in [0, 10], got {d}")
        for flag in ("nav_filter", "measured_thrust"):
            if getattr(self, flag) not in (0.0, 1.0):
                raise ValueError(f"shield {flag} must be 0 or 1, got {getattr(self, flag)}")
        if not (self.touchdown_speed_mps == 0.0 or 0.1 <= self.touchdown_speed_mps < 2.0):
            raise ValueError(
                "shield touchdown_speed_mps must be 0 or in [0.1, 2), "
                f"got {self.touchdown_speed_mps}"
            )

    def to_dict(self) -> dict[str, float]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ShieldParams:
        unknown = set(d) - set(cls.__dataclass_fields__)
        if unknown:
            raise ValueError(f"unknown shield setting(s): {', '.join(sorted(unknown))}")
        return cls(**{k: float(v) for k, v in d.items()})


def max_descent_speed_mps(
    altitude_m: np.ndarray,
    mass_kg: np.ndarray,
    max_vertical_thrust_n: float | np.ndarray,
    p: ShieldParams,
) -> np.ndarray:
    """Fastest descent speed (m/s, >= 0) from which the margin thrust still brakes to the land
    speed by the pad; the land speed itself where the lander cannot brake at all."""
    a_net = p.thrust_margin * max_vertical_thrust_n / np.asarray(mass_kg, dtype=float) - _G_MPS2
    z = np.maximum(np.asarray(altitude_m, dtype=float), 0.0)
    return np.sqrt(p.land_speed_mps**2 + 2.0 * np.maximum(a_net, 0.0) * z)


def shield_mask(
    states: np.ndarray,
    vertical_thrust_n: np.ndarray,
    max_vertical_thrust_n: float | np.ndarray,
    p: ShieldParams,
) -> np.ndarray:
    """(B,) True where the (observed) physical states (B, 7), after one step of the commanded
    vertical thrust (B,) at the margin, would descend beyond the braking limit. Looking one
    step ahead matters: a shield that fired only once the limit is crossed could never catch
    up, since braking at the margin thrust merely keeps the excess speed."""
    s = np.atleast_2d(states)
    a_z = p.thrust_margin * np.asarray(vertical_thrust_n, dtype=float) / s[:, 6] - _G_MPS2
    vz = s[:, 5] + a_z * DT_S
    z = s[:, 2] + (s[:, 5] + 0.5 * a_z * DT_S) * DT_S
    over = -vz > max_descent_speed_mps(z, s[:, 6], max_vertical_thrust_n, p)
    # a step that ends on the ground is judged by the speed of the touchdown, not by the speed
    # a whole step would reach below the pad
    if p.touchdown_speed_mps <= 0.0:
        return over
    touchdown_sq = s[:, 5] ** 2 - 2.0 * a_z * np.maximum(s[:, 2], 0.0)
    return np.where(z <= 0.0, touchdown_sq > p.touchdown_speed_mps**2, over)


def guard_mask(
    states: np.ndarray, vertical_levels: np.ndarray, p: ShieldParams, raised_thrust_n: float
) -> np.ndarray:
    """(B,) True where the (observed) physical states (B, 7) are below the guard altitude,
    descending, and the vertical level (B,) is the lowest (zero thrust: free fall). Where the
    raised level (`raised_thrust_n`, N) would climb faster than `GUARD_CLIMB_MPS2` at the
    lander's mass, only a descent faster than the land speed counts (see the module docstring)."""
    s = np.atleast_2d(states)
    climbs = raised_thrust_n / s[:, 6] - _G_MPS2 > GUARD_CLIMB_MPS2
    slowest = np.where(climbs, p.land_speed_mps, 0.0)
    return (
        (s[:, 2] < p.guard_altitude_m) & (s[:, 5] < -slowest) & (np.asarray(vertical_levels) == 0)
    )


def handover_mask(states: np.ndarray, max_thrust_n: np.ndarray, p: ShieldParams) -> np.ndarray:
    """(B,) True where the (observed) physical states (B, 7) are above the handover altitude and
    the teacher's lateral limit binds (`pd_core.controllers.lateral_brake_accel_mps2` below the
    teacher's braking deceleration at full thrust `max_thrust_n` (3,), N), or lighter than the
    handover mass."""
    s = np.atleast_2d(states)
    light = s[:, 6] < p.handover_mass_kg
    if p.handover_altitude_m <= 0.0:
        return light
    a_brake = braking_accel_mps2(s[:, 6], VERNIER_PARAMS, float(max_thrust_n[2]))
    binds = lateral_brake_accel_mps2(s, VERNIER_PARAMS, max_thrust_n) < a_brake
    return ((s[:, 2] > p.handover_altitude_m) & binds) | light


def delivered_fraction(scale: np.ndarray | None, n: int, p: ShieldParams) -> np.ndarray:
    """(n,) fraction of the commanded vertical thrust the braking limit counts on being
    delivered: the measured `scale` (n,) where it is below 1 and `p.measured_thrust` is on,
    floored at MIN_MEASURED_THRUST; else 1 (a measured surplus is never counted on)."""
    if scale is None or not p.measured_thrust:
        return np.ones(n)
    return np.clip(np.asarray(scale, dtype=float), MIN_MEASURED_THRUST, 1.0)


def shield_actions(
    actions: np.ndarray,
    states: np.ndarray,
    space: ActionSpace,
    p: ShieldParams,
    vertical_thrust_scale: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(shielded actions in the shape of `actions`, flat mask of the overridden ones) for
    actions (...) chosen in physical states (..., 7): the teacher's action where
    `handover_mask`; then full vertical thrust where `shield_mask`, else one vertical level up
    where `guard_mask` (the teacher flies behind the same limits). `vertical_thrust_scale`
    (flat, optional): the delivered fraction of commanded vertical thrust measured in flight
    (`pd_core.latency`), which the braking limit counts on where it is short."""
    shape = np.shape(actions)
    a = np.asarray(actions, dtype=np.int64).reshape(-1)
    s = np.reshape(states, (-1, 7))
    hand = handover_mask(s, space.limits.hi, p)
    if hand.any():
        a = a.copy()
        a[hand] = ZemZevController(VERNIER_PARAMS, space).act_batch(s[hand])
    levels = space.level_table[a]
    frac = delivered_fraction(vertical_thrust_scale, len(a), p)
    fire = shield_mask(s, frac * space.table_n[a, 2], frac * float(space.limits.hi[2]), p)
    raised = float(space.levels_to_thrust(np.array([0, 0, 1]))[2])
    guard = guard_mask(s, levels[:, 2], p, raised) & ~fire
    if not (fire.any() or guard.any()):
        return a.reshape(shape), fire | hand
    levels = levels.copy()
    levels[fire, 2] = space.n_per_axis[2] - 1
    levels[guard, 2] = 1
    return space.levels_to_action(levels).astype(np.int64).reshape(shape), fire | guard | hand


def latency_for(p: ShieldParams | None) -> LatencyCompensator | None:
    """The latency compensation a shield asks for (None: none)."""
    if p is None or (p.max_delay_steps <= 0 and not p.nav_filter):
        return None
    return LatencyCompensator(int(p.max_delay_steps), nav_filter=bool(p.nav_filter))


class ShieldedActor(CompensatesLatency):
    """Any actor (`act_batch` on physical states -> action indices of `space`) behind the shield,
    so that a reference controller can be flown behind the same runtime assurance as a policy
    (a like-for-like comparison: `pd-eval ... --compare shield:controller:zemzev`), latency
    compensation included."""

    def __init__(
        self, actor: Any, p: ShieldParams | None = None, space: ActionSpace | None = None
    ) -> None:
        self.actor = actor
        self.shield = p or ShieldParams()
        self.actions = space or actor.actions
        self.name = f"{getattr(actor, 'name', 'actor')}+shield"
        self.shield_fired = 0
        """steps on which the shield overrode the actor or handed it over (since construction)"""
        self.latency = latency_for(self.shield)

    def act_batch(
        self, states: np.ndarray, vertical_thrust_scale: np.ndarray | None = None
    ) -> np.ndarray:
        out, fired = shield_actions(
            self.actor.act_batch(states), states, self.actions, self.shield, vertical_thrust_scale
        )
        self.shield_fired += int(fired.sum())
        return out

    def act(self, state: np.ndarray) -> int:
        return int(self.act_batch(np.asarray(state, dtype=float).reshape(1, 7))[0])

    def thrust(self, action: int) -> np.ndarray:
        return self.actions.thrust(int(action))

    def __getattr__(self, name: str) -> Any:  # reset(), stats, params of the wrapped actor
        actor = self.__dict__.get("actor")
        if actor is None:  # not constructed (e.g. while unpickling)
            raise AttributeError(name)
        return getattr(actor, name)


def with_settings(actor: Any, settings: str) -> Any:
    """The actor (a policy or a `ShieldedActor`) with the runtime-layer settings "K=V,K=V"
    (`ShieldParams` fields) changed: pd-eval's `set:` specs and the policy node's
    `shield_settings`. ValueError in one line for an actor without that layer or a bad setting."""
    if getattr(actor, "shield", None) is None:
        raise ValueError(
            f"runtime settings {settings!r}: the agent has no runtime layer to change (a policy "
            "file that asks for the braking shield, or one flown behind it, has)"
        )
    changes: dict[str, float] = {}
    for item in filter(None, settings.split(",")):
        key, eq, value = item.partition("=")
        try:
            changes[key.strip()] = float(value)
        except ValueError:
            eq = ""
        if not eq:
            raise ValueError(f"runtime settings {settings!r}: {item!r} is not KEY=NUMBER")
    try:
        actor.shield = ShieldParams.from_dict({**actor.shield.to_dict(), **changes})
    except ValueError as exc:
        raise ValueError(f"runtime settings {settings!r}: {exc}") from None
    actor.latency = latency_for(actor.shield)
    return actor
