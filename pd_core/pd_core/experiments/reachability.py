"""Per-episode reachability oracle: could any thrust schedule have landed campaign episode i?

Issue 10 lets a scenario leave out of its 99 % target the episodes that are physically out of
reach, with evidence. An episode is judged from its true start (the state and plant draws that
`pd_core.episodes.rollout` flew, rebuilt by `episode_starts`) in the plant model without
disturbance, by two one-sided tests:

* **Reachable** (a sufficient condition): a `pd_core.ocp` plan within the episode's delivered
  thrust limits (the RL limits times the per-thruster gain: the plant delivers gain x command),
  re-flown by the plant's step function, meets the landing condition of Eq. 12 at its first
  touchdown. Eq. 4 has no altitude constraint (Sec. 2.1), so a converged OCP alone proves
  nothing: from any state its "landing" may pass through the ground and climb back (from
  z = 300 m at -100 m/s the fuel optimum bottoms out ~1.8 km underground). Attempts, in order:
  fuel then energy to the pad, then both to rest 10 m and 50 m above it finished by a 1 m/s
  descent (a plan that dips below or skims the ground before the pad crashes in the plant).
* **Out of reach** (a proof): `touchdown_speed_bound` flies the most optimistic lander there
  is: from the first powered step, the largest upward force the misaligned, gain-scaled
  thrusters can deliver, while the mass (hence the weight to brake) falls at the largest rate
  any command burns, at the episode's Isp. Any schedule's vertical velocity stays below that
  flight's at every step end, so if that flight still reaches the ground at >= 2 m/s (Eq. 12),
  no schedule lands.

An episode that neither test settles is "undecided": the OCP found no landing, but the bound
does not exclude one (it lets the lander burn sideways fuel only to get lighter, and lift with
the misaligned lateral thrusters; the OCP's local solvers do neither). Campaigns count only
proven episodes as out of reach.

What the OCP plan does not model, and why that is acceptable (the proof models all but the
disturbance, so only "reachable" verdicts carry these approximations):
- Isp: `pd_core.ocp` has Eq. 3's 210 s built in. A lower Isp burns mass faster, so the real
  lander is lighter and brakes better than the plan assumes (the plan is pessimistic); a higher
  one the other way. +-5 % of Isp changes the ~250 kg of a braking burn by ~12 kg, ~0.6 % of
  the mass, hence ~0.6 % of the braking authority.
- Misalignment (<= 2 deg): costs at most 1 - cos(2 deg) = 0.06 % of each thruster's axial
  thrust; ignored.
- Delay: the FIFO is filled with zero thrust at reset, so the first `delay_steps` steps are
  flown unpowered whatever is commanded; both tests start after them. Past that, a known delay
  and navigation noise do not change what perfect knowledge can fly (commands can be issued
  early; noise only corrupts what the agent observes).
- Disturbance: left out of both (zero-mean; 300 N per axis in `all`, ~2 % of the 13 kN, and
  its average over a 30 s braking burn a fraction of that).
- A thrust factor (`Dispersions.thrust_factor`) that starts mid-flight: the plan counts on the
  weakest gains of the episode throughout, the proof on the strongest (`plan_gains`), so both
  tests stay one-sided.
- A steady wind (`Dispersions.wind_force_n`, horizontal): the plan's horizontal limits are the
  delivered ones shifted by the wind (what the thrusters can add to it). The plan burns mass on
  its own force, the lander on force minus wind: at 400 N at most 0.2 kg/s less or more, about
  10 kg over a landing (0.5 % of the mass). The proof is vertical: the wind does not enter.
- A navigation bias, like the noise, only corrupts what the agent observes.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from pd_core import ocp
from pd_core.config import (
    DRY_MASS_KG,
    DT_S,
    GRAVITY_MPS2,
    ISP_S,
    MAX_EPISODE_TIME_S,
    REWARD,
    RL_THRUST,
    ThrustLimits,
)
from pd_core.dispersions import Dispersions, EpisodeDraws
from pd_core.dynamics import step
from pd_core.episodes import Rollouts
from pd_core.reward import landed
from pd_core.vector_env import make_vector_env

Status = Literal["reachable", "out-of-reach", "undecided"]
# ours: plans that end at rest this high above the pad (a fuel optimum may dip a few metres below
# its target and climb back), finished by a descent at DESCENT_RATE_MPS (Eq. 12 allows < 2 m/s)
GATES_M = (10.0, 50.0)
DESCENT_RATE_MPS = 1.0
_ZERO = np.zeros(3)


# --- episode starts -----------------------------------------------------------------------------


def episode_starts(
    scenario: Dispersions,
    seed: int,
    indices: Iterable[int],
    max_time_s: float = MAX_EPISODE_TIME_S,
) -> tuple[np.ndarray, list[EpisodeDraws]]:
    """(true initial states (n, 7) [r m, v m/s, mass kg], draws) of episodes `indices` of
    `rollout(actor, N, seed, dispersions=scenario)`: episode i runs on env seed seed + i.

    The env itself resets them (one sub-env per episode, seeded seed + i), so the draws are
    the ones flown by construction. `max_time_s` must be the campaign's: it sets how many
    disturbance knots each reset draws before the dispersions.
    """
    idx = [int(i) for i in indices]
    if not idx:
        return np.zeros((0, 7)), []
    env = make_vector_env(len(idx), max_time_s=max_time_s, autoreset=False, dispersions=scenario)
    env.reset(seed=[seed + i for i in idx])
    sd = env.state_dict()
    rot, nav = sd.get("rotation"), sd.get("nav_noise")
    factor, onset = sd.get("thrust_factor"), sd.get("thrust_onset_step")
    bias, wind = sd.get("nav_bias"), sd.get("wind_n")
    draws = [
        EpisodeDraws(
            mass_kg=None if scenario.mass_kg is None else float(env.states[j, 6]),
            thrust_gain=sd["thrust_gain"][j].copy(),
            isp_s=float(sd["isp_s"][j]),
            rotation=np.eye(3) if rot is None else rot[j].copy(),
            nav_noise=nav[j].copy() if nav is not None and scenario.has_nav_noise else None,
            thrust_factor=1.0 if factor is None else float(factor[j]),
            thrust_onset_step=0 if onset is None else int(onset[j]),
            nav_bias=None if bias is None or not scenario.has_nav_bias else bias[j].copy(),
            wind_n=None if wind is None or not scenario.wind_force_n else wind[j].copy(),
        )
        for j in range(len(idx))
    ]
    return env.initial_states.copy(), draws


def plan_gains(draws: EpisodeDraws) -> tuple[np.ndarray, np.ndarray]:
    """(weakest, strongest) delivered / commanded thrust (3,) per thruster over an episode: the
    per-thruster gains times the thrust factor, before its onset times 1."""
    g = np.asarray(draws.thrust_gain, dtype=float)
    f = draws.thrust_factor
    if draws.thrust_onset_step <= 0:
        return g * f, g * f
    return g * min(f, 1.0), g * max(f, 1.0)


def delivered_limits(
    thrust_gain: np.ndarray, limits: ThrustLimits = RL_THRUST, wind_n: np.ndarray | None = None
) -> ThrustLimits:
    """Per-axis force (N) the plant can put on the lander: the command limits times the gains,
    plus a steady force `wind_n` (3,) where given."""
    g = np.asarray(thrust_gain, dtype=float)
    w = np.zeros(3) if wind_n is None else np.asarray(wind_n, dtype=float)
    return ThrustLimits(tuple((limits.lo * g + w).tolist()), tuple((limits.hi * g + w).tolist()))


def unpowered(state: np.ndarray, steps: int, wind_n: np.ndarray | None = None) -> np.ndarray:
    """State (7,) after `steps` steps without thrust or disturbance (the delay FIFO's zeros),
    under the steady force `wind_n` (3,) N where given."""
    s = np.asarray(state, dtype=float)
    force = _ZERO if wind_n is None else np.asarray(wind_n, dtype=float)
    for _ in range(steps):
        s = step(s, _ZERO, force, DT_S)
    return s


# --- the proof: the most optimistic braking --------------------------------------------------


def braking_authority(
    thrust_gain: np.ndarray, rotation: np.ndarray | None = None
) -> tuple[float, float]:
    """(largest upward force N, largest |thrust|_1 N) the plant can deliver: commands in the RL
    box, times the gains, rotated by the misalignment. The plant burns mass on the delivered
    vector's |.|_1 (Eq. 3), so a rotation can raise both; a convex function of the command
    peaks at a corner of the box, so the 8 corners give the exact maxima."""
    corners = np.array(np.meshgrid(*zip(RL_THRUST.lo, RL_THRUST.hi, strict=True))).reshape(3, -1)
    rot = np.eye(3) if rotation is None else np.asarray(rotation, dtype=float)
    delivered = rot @ (np.asarray(thrust_gain, dtype=float)[:, None] * corners)
    return float(delivered[2].max()), float(np.abs(delivered).sum(axis=0).max())


def touchdown_speed_bound(
    state0: np.ndarray,
    thrust_gain: np.ndarray,
    isp_s: float = ISP_S,
    delay_steps: int = 0,
    max_time_s: float = MAX_EPISODE_TIME_S,
    rotation: np.ndarray | None = None,
) -> float:
    """A lower bound (m/s, >= 0) on the vertical speed at which any thrust schedule reaches the
    ground from state0 within the episode; 0 when the bound cannot rule out stopping above it.

    Flies the largest upward force from the first powered step while burning mass at the largest
    rate (`braking_authority`; every thruster at full), at `isp_s` and without disturbance: at
    each step end no admissible schedule has a higher vertical velocity (its upward force is at
    most this, its mass at least this flight's, the plant holds each command for a step). So vz
    at the real touchdown, which comes no later than this flight's, is at most this flight's
    best vz up to its touchdown. Inconclusive (0) if this flight runs dry first.
    """
    up_n, l1_n = braking_authority(thrust_gain, rotation)
    full = np.array([l1_n - up_n, 0.0, up_n])  # |full|_1 = l1_n: the largest mass flow
    s = np.asarray(state0, dtype=float)
    best = -math.inf
    for k in range(round(max_time_s / DT_S)):
        s = step(s, full if k >= delay_steps else _ZERO, _ZERO, DT_S, isp_s=isp_s)
        best = max(best, float(s[5]))
        if best >= 0.0 or s[6] <= DRY_MASS_KG:
            return 0.0
        if s[2] < REWARD.touchdown_altitude_m:
            break
    return max(0.0, -best)


# --- the sufficient test: an OCP plan that lands -----------------------------------------------


def _lands(states: np.ndarray) -> bool:
    """Eq. 12 at the first step end below the touchdown altitude (none: no landing)."""
    down = np.flatnonzero(states[:, 2] < REWARD.touchdown_altitude_m)
    if not len(down):
        return False
    s = states[down[0]]
    return bool(landed(s[0:3], s[3:6]))


def _descend(s: np.ndarray, lim: ThrustLimits, max_steps: int) -> np.ndarray:
    """States (n+1, 7) from s to the ground, each step commanding the velocity
    [0, 0, -DESCENT_RATE_MPS] (deadbeat, within the limits lim)."""
    out = [s]
    want = np.array([0.0, 0.0, -DESCENT_RATE_MPS])
    for _ in range(max_steps):
        thrust = np.clip(s[6] * ((want - s[3:6]) / DT_S - GRAVITY_MPS2), lim.lo, lim.hi)
        s = step(s, thrust, _ZERO, DT_S)
        out.append(s)
        if s[2] < REWARD.touchdown_altitude_m:
            break
    return np.array(out)


def _plan(
    s: np.ndarray, lim: ThrustLimits, objective: str, gate_m: float, max_time_s: float
) -> tuple[ocp.OCPResult, bool]:
    """(OCP result to rest gate_m above the pad, whether that plan re-flown from s, then a slow
    descent if it ends above the ground, lands within max_time_s)."""
    res = ocp.solve(s[0:3] - [0.0, 0.0, gate_m], s[3:6], s[6], objective=objective, limits=lim)
    if not res.success:
        return res, False
    states = res.states + np.array([0.0, 0.0, gate_m, 0.0, 0.0, 0.0, 0.0])
    t_s = res.time_of_flight
    if states[:, 2].min() >= REWARD.touchdown_altitude_m:
        tail = _descend(states[-1], lim, round(max_time_s / DT_S))
        states = np.concatenate([states, tail[1:]])
        t_s += (len(tail) - 1) * DT_S
    return res, _lands(states) and t_s <= max_time_s


# (objective, gate altitude m) of the OCP plans tried, in order
ATTEMPTS = tuple((obj, gate) for gate in (0.0, *GATES_M) for obj in ("fuel", "energy"))


@dataclass(frozen=True)
class Verdict:
    """Whether one episode can land, and the evidence."""

    status: Status
    touchdown_speed_bound_mps: float  # no schedule reaches the ground slower than this
    fuel_ocp_min_altitude_m: float  # lowest altitude of the converged fuel optimum (nan: none)
    plan: str = ""  # the attempt that landed, e.g. "fuel" or "energy, 10 m gate"
    plan_fuel_kg: float = math.nan
    message: str = ""

    @property
    def out_of_reach(self) -> bool:
        return self.status == "out-of-reach"

    def to_dict(self) -> dict[str, Any]:
        return {
            k: (None if isinstance(v, float) and math.isnan(v) else v)
            for k, v in vars(self).items()
        }


def reachable(
    state0: np.ndarray,
    thrust_gain: np.ndarray,
    isp_s: float = ISP_S,
    delay_steps: int = 0,
    max_time_s: float = MAX_EPISODE_TIME_S,
    rotation: np.ndarray | None = None,
    *,
    wind_n: np.ndarray | None = None,
    bound_thrust_gain: np.ndarray | None = None,
) -> Verdict:
    """Can a lander starting at state0 (7,) [r m, v m/s, mass kg], whose thrusters deliver
    thrust_gain (3,) x their command at Isp isp_s (s), rotated by `rotation` (3, 3), after
    delay_steps unpowered 0.2 s steps, land within max_time_s without disturbance (but with the
    steady horizontal force `wind_n` (3,) N)? See the module docstring for the two tests; the
    proof counts on `bound_thrust_gain` (3,) where the gains change in flight (default:
    thrust_gain).

    The fuel optimum to the pad is always solved: for an episode out of reach it is the
    evidence (it fails, or reaches the pad only through the ground). The proof wins over an OCP
    plan (flown at Isp 210 s, unrotated), which can only disagree within those errors.
    """
    lim = delivered_limits(thrust_gain, wind_n=wind_n)
    s = unpowered(state0, delay_steps, wind_n)
    horizon_s = max_time_s - delay_steps * DT_S
    top = thrust_gain if bound_thrust_gain is None else bound_thrust_gain
    bound = touchdown_speed_bound(state0, top, isp_s, delay_steps, max_time_s, rotation)
    res, ok = _plan(s, lim, "fuel", 0.0, horizon_s)
    zmin = float(res.states[:, 2].min()) if res.success else math.nan
    if bound >= REWARD.v_lim_mps:
        msg = f"full thrust reaches the ground at >= {bound:.1f} m/s (Eq. 12: < 2); " + (
            f"the fuel optimum dips to {zmin:.0f} m" if res.success else f"fuel: {res.message}"
        )
        if ok:
            msg += f"; its plan lands at Isp {ISP_S:g} s, unrotated (episode: {isp_s:.1f} s)"
        return Verdict("out-of-reach", bound, zmin, message=msg)
    tried = []
    for k, (objective, gate) in enumerate(ATTEMPTS):
        if k:
            res, ok = _plan(s, lim, objective, gate, horizon_s)
        name = objective if gate == 0.0 else f"{objective}, {gate:g} m gate"
        if ok:
            return Verdict("reachable", bound, zmin, name, res.fuel, f"landed by {name}")
        tried.append(f"{name}: {res.message if not res.success else 'no landing'}")
    return Verdict("undecided", bound, zmin, message="; ".join(tried))


# --- campaigns ------------------------------------------------------------------------------


@dataclass
class ScenarioReach:
    """The episodes of one scenario that failed for some agent, and their verdicts."""

    checked: list[int] = field(default_factory=list)
    verdicts: dict[int, Verdict] = field(default_factory=dict)

    @property
    def out_of_reach(self) -> list[int]:
        return [i for i in self.checked if self.verdicts[i].out_of_reach]

    @property
    def undecided(self) -> list[int]:
        return [i for i in self.checked if self.verdicts[i].status == "undecided"]


def failed_episodes(cells: Mapping[str, Rollouts]) -> list[int]:
    """Episode indices that at least one agent (cells: agent -> Rollouts) did not land."""
    failed = np.zeros(len(next(iter(cells.values())).landed), dtype=bool)
    for ro in cells.values():
        failed |= ~ro.landed
    return [int(i) for i in np.flatnonzero(failed)]


def campaign_reachability(
    flown: Mapping[str, Mapping[str, Rollouts]],
    scenarios: list[Dispersions],
    seed: int,
    max_time_s: float = MAX_EPISODE_TIME_S,
    on_episode: Callable[[], None] | None = None,
) -> dict[str, ScenarioReach]:
    """{scenario: ScenarioReach} of a campaign ({scenario: {agent: Rollouts}}, episode i on
    seed + i). Only episodes some agent failed are judged (a solve costs 0.1-1 s; a landed
    episode is reachable). ValueError if the rebuilt starts differ from the flown ones (the
    campaign was not flown with this seed or max_time_s)."""
    out = {}
    for d in scenarios:
        cells = flown[d.name]
        idx = failed_episodes(cells)
        states, draws = episode_starts(d, seed, idx, max_time_s)
        flown_init = next(iter(cells.values())).initial_states[idx]
        if not np.array_equal(states, flown_init):
            raise ValueError(f"{d.name}: rebuilt episode starts differ from the flown ones")
        rep = ScenarioReach(checked=idx)
        for i, s, dr in zip(idx, states, draws, strict=True):
            weakest, strongest = plan_gains(dr)
            rep.verdicts[i] = reachable(
                s, weakest, dr.isp_s, d.delay_steps, max_time_s, dr.rotation,
                wind_n=dr.wind_n, bound_thrust_gain=strongest,
            )  # fmt: skip
            if on_episode is not None:
                on_episode()
        out[d.name] = rep
    return out


__all__ = [
    "ATTEMPTS",
    "GATES_M",
    "ScenarioReach",
    "Verdict",
    "braking_authority",
    "campaign_reachability",
    "delivered_limits",
    "episode_starts",
    "failed_episodes",
    "plan_gains",
    "reachable",
    "touchdown_speed_bound",
    "unpowered",
]
