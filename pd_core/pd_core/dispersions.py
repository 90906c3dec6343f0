"""Dispersions: what a flight team varies before it trusts a guidance law (off by default).

A `Dispersions` is a frozen description of one scenario. The environments sample its random parts
once per episode at reset, from the episode's own seeded Generator and after the nominal draws
(initial state, then disturbance knots), so:

- a nominal scenario draws nothing more: nominal episodes are bit-identical to an env without
  dispersions;
- every non-nominal scenario makes the same fixed set of draws in the same order, whichever of
  its parts are on, so episode i of scenario `mass` and episode i of scenario `all` share their
  initial state, gusts and mass (common random numbers: scenarios compare with less noise);
- stepping needs no random numbers (the navigation noise of the episode is drawn at reset).

The parts added for issue 68 (`thrust_factor`, its onset, the navigation bias, the steady wind)
draw from a second stream seeded by the episode's navigation seed, and only in scenarios that use
one of them: every scenario without them flies exactly what it flew before they existed, and the
scenarios with them share those draws too (in a fixed order: factor, onset, the position bias's
direction and size, the velocity bias's, the wind's direction).

The magnitudes of `SCENARIOS` are ours, chosen at or beyond what flight Monte Carlo campaigns use
(each field says why). `load_scenarios` reads a scenario name, a comma-separated list, the
campaign `standard`, or a YAML file.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from pd_core.config import DT_S, ISP_S, TABLE3, StateRange

STATE_DIM = 7
# per-episode draws of a non-nominal scenario, in this order: mass (1 uniform), thruster gains
# (3 uniforms), Isp (1 uniform), misalignment axis (3 normals) and angle (1 uniform), the seed of
# the episode's navigation-noise stream (1 integer). Scenarios with an issue-68 part then draw
# from a stream seeded by [that integer, 68]: factor (1 uniform), onset (1 uniform), position bias
# direction (3 normals) and size (1 uniform), velocity bias the same, wind direction (1 uniform).


@dataclass(frozen=True)
class Dispersions:
    """One dispersion scenario. Defaults are the nominal problem (Table 3, sigma 100 N)."""

    name: str = "nominal"
    mass_kg: tuple[float, float] | None = None
    """initial (wet) mass drawn uniformly in this range (kg) instead of Table 3's 2000 kg.
    `mass`: 1800-2200 kg, +-10 %: the propellant left after entry and the parachute phase is
    known to a few percent at best; +-10 % covers an off-nominal earlier phase."""
    thrust_error: float = 0.0
    """each of the three thrusters delivers (1 + e) times its command, e uniform in
    [-thrust_error, +thrust_error], per thruster and per episode. `thrust`: 5 %; throttleable
    engines are characterised to about 1-3 % (3 sigma); a uniform 5 % puts more weight on the
    edges than a Gaussian would."""
    isp_error: float = 0.0
    """specific impulse (1 + e) * 210 s, e uniform in [-isp_error, +isp_error] per episode: the
    mass flow of Eq. 3 for the same thrust. `isp`: 5 %, against a typical 1-2 % (3 sigma)."""
    misalignment_deg: float = 0.0
    """the delivered thrust vector is rotated by an angle uniform in [0, misalignment_deg]
    about a uniformly random axis, fixed for the episode. `misalignment`: 2 deg; engine
    alignment tolerances are 0.25-0.5 deg, 2 deg adds mounting and structural deflection; at
    13 kN it is a 450 N side force, 4.5x the disturbance sigma."""
    delay_steps: int = 0
    """the plant executes the command issued this many 0.2 s steps earlier (a FIFO per lander,
    filled with zero thrust at reset: engines not yet lit). `delay`: 1 step = 200 ms, a whole
    guidance cycle against the 10-50 ms of flight computer and bus latency."""
    nav_position_sigma_m: float = 0.0
    """white Gaussian error (m, per axis, per step) on the position the agent observes.
    `nav-noise`: 1 m; terrain-relative navigation and radar altimetry give sub-metre to metre
    knowledge near the surface. The true state decides landing."""
    nav_velocity_sigma_mps: float = 0.0
    """white Gaussian error (m/s, per axis, per step) on the observed velocity. `nav-noise`:
    0.1 m/s, the class of a Doppler radar velocimeter."""
    nav_mass_sigma_kg: float = 0.0
    """white Gaussian error (kg, per step) on the observed mass. `nav-noise`: 10 kg (0.5 %),
    mass being estimated by integrating commanded flow."""
    disturbance_scale: float = 1.0
    """multiplies the disturbance sigma of Sec. 3.2 (100 N). `gusts`: 3 (300 N per axis, a
    0.15 m/s^2 sustained push on a 2000 kg lander)."""
    box_widen: float = 0.0
    """the initial-state box is Table 3 widened by this fraction of its width on each side of
    every varied component (mass excluded). `wide-box`: 0.25 (x 225-1275 m, y +-1650 m,
    z 2350-2650 m, vx -92.5..12.5, vy +-52.5, vz -102.5..-57.5 m/s)."""
    thrust_factor: tuple[float, float] | None = None
    """one factor f, uniform in this range and the same for the three thrusters, multiplies
    every delivered thrust (after `thrust_error`), unknown to the policy. `data/beyond.yaml`:
    0.8-1.0, an engine anywhere between the weakest promised and nominal."""
    thrust_factor_onset_s: tuple[float, float] | None = None
    """the factor takes effect at a time uniform in this range (s from the episode's start,
    whole steps: before it the engine delivers nominal thrust); None: from ignition."""
    nav_position_bias_m: float = 0.0
    """a constant error on the observed position for the whole episode: size uniform in
    [0, this] m, direction uniform on the sphere. Unlike the white noise, no filter can
    average it out."""
    nav_velocity_bias_mps: float = 0.0
    """a constant error on the observed velocity: size uniform in [0, this] m/s, direction
    uniform on the sphere (independent of the position bias's)."""
    wind_force_n: float = 0.0
    """a steady horizontal force of this size (N), in a uniformly random horizontal direction
    fixed for the episode, added to the disturbance of Sec. 3.2 (and applied without it)."""

    def __post_init__(self) -> None:
        if self.mass_kg is not None:
            lo, hi = (float(v) for v in self.mass_kg)
            if not 0.0 < lo <= hi:
                raise ValueError(
                    f"{self.name}: mass_kg must be 0 < low <= high, got {self.mass_kg}"
                )
            object.__setattr__(self, "mass_kg", (lo, hi))
        if self.thrust_factor is not None:
            lo, hi = (float(v) for v in self.thrust_factor)
            if not 0.0 < lo <= hi <= 2.0:
                raise ValueError(
                    f"{self.name}: thrust_factor must be 0 < low <= high <= 2, "
                    f"got {self.thrust_factor}"
                )
            object.__setattr__(self, "thrust_factor", (lo, hi))
        if self.thrust_factor_onset_s is not None:
            lo, hi = (float(v) for v in self.thrust_factor_onset_s)
            if self.thrust_factor is None or not 0.0 <= lo <= hi:
                raise ValueError(
                    f"{self.name}: thrust_factor_onset_s must be 0 <= low <= high, with a "
                    f"thrust_factor, got {self.thrust_factor_onset_s}"
                )
            object.__setattr__(self, "thrust_factor_onset_s", (lo, hi))
        for f in ("thrust_error", "isp_error"):
            if not 0.0 <= getattr(self, f) < 1.0:
                raise ValueError(f"{self.name}: {f} must be in [0, 1), got {getattr(self, f)}")
        checks = {
            "misalignment_deg": 0.0 <= self.misalignment_deg <= 90.0,
            "delay_steps": isinstance(self.delay_steps, int) and 0 <= self.delay_steps <= 50,
            "nav_position_sigma_m": self.nav_position_sigma_m >= 0.0,
            "nav_velocity_sigma_mps": self.nav_velocity_sigma_mps >= 0.0,
            "nav_mass_sigma_kg": self.nav_mass_sigma_kg >= 0.0,
            "disturbance_scale": self.disturbance_scale >= 0.0,
            "box_widen": 0.0 <= self.box_widen <= 10.0,
            "nav_position_bias_m": self.nav_position_bias_m >= 0.0,
            "nav_velocity_bias_mps": self.nav_velocity_bias_mps >= 0.0,
            "wind_force_n": 0.0 <= self.wind_force_n <= 1e4,
        }
        bad = [f"{k}={getattr(self, k)!r}" for k, ok in checks.items() if not ok]
        if bad:
            raise ValueError(f"{self.name}: out of range: {', '.join(bad)}")

    @property
    def nominal(self) -> bool:
        """True when every part is off (the name does not count)."""
        return replace(self, name="nominal") == NOMINAL

    @property
    def nav_sigma(self) -> np.ndarray:
        """Observation noise sigma (7,) of [x, y, z, vx, vy, vz, m]."""
        p, v = self.nav_position_sigma_m, self.nav_velocity_sigma_mps
        return np.array([p, p, p, v, v, v, self.nav_mass_sigma_kg])

    @property
    def has_nav_noise(self) -> bool:
        return bool(np.any(self.nav_sigma > 0.0))

    @property
    def has_nav_bias(self) -> bool:
        return self.nav_position_bias_m > 0.0 or self.nav_velocity_bias_mps > 0.0

    @property
    def has_issue68_parts(self) -> bool:
        """True where the scenario draws from the second stream (see the module docstring)."""
        return self.thrust_factor is not None or self.has_nav_bias or self.wind_force_n > 0.0

    def initial_box(self, base: StateRange = TABLE3) -> StateRange:
        """`base` widened by `box_widen` of its width on each side (mass excluded)."""
        if self.box_widen == 0.0:
            return base
        pad = self.box_widen * (base.hi - base.lo)
        pad[6] = 0.0
        return StateRange(tuple((base.lo - pad).tolist()), tuple((base.hi + pad).tolist()))

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        for f in ("mass_kg", "thrust_factor", "thrust_factor_onset_s"):
            d[f] = None if d[f] is None else list(d[f])
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Dispersions:
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ValueError(f"unknown dispersion field(s) {unknown}; known: {sorted(known)}")
        d = dict(d)
        for f in ("mass_kg", "thrust_factor", "thrust_factor_onset_s"):
            if d.get(f) is not None:
                d[f] = tuple(d[f])
        if "delay_steps" in d:
            d["delay_steps"] = int(d["delay_steps"])
        return cls(**d)


NOMINAL = Dispersions()
_NAV = {"nav_position_sigma_m": 1.0, "nav_velocity_sigma_mps": 0.1, "nav_mass_sigma_kg": 10.0}
SCENARIOS: dict[str, Dispersions] = {
    d.name: d
    for d in (
        NOMINAL,
        Dispersions("mass", mass_kg=(1800.0, 2200.0)),
        Dispersions("thrust", thrust_error=0.05),
        Dispersions("isp", isp_error=0.05),
        Dispersions("misalignment", misalignment_deg=2.0),
        Dispersions("delay", delay_steps=1),
        Dispersions("nav-noise", **_NAV),
        Dispersions("gusts", disturbance_scale=3.0),
        Dispersions("wide-box", box_widen=0.25),
        Dispersions(
            "all",
            mass_kg=(1800.0, 2200.0),
            thrust_error=0.05,
            isp_error=0.05,
            misalignment_deg=2.0,
            delay_steps=1,
            disturbance_scale=3.0,
            box_widen=0.25,
            **_NAV,
        ),
    )
}
STANDARD = tuple(SCENARIOS)
# Training only (ours): the standard scenarios plus harsher versions of each part, so a policy
# trained on them has seen beyond the campaign it is judged on. 2300 kg is the heaviest lander
# full thrust can still stop from Table 3's worst state (1.93 m/s^2 net: 2.6 km from 100 m/s).
_NAV2 = {k: 2.0 * v for k, v in _NAV.items()}
BROAD_EXTRA = (
    Dispersions("mass-broad", mass_kg=(1600.0, 2300.0)),
    Dispersions("thrust-8", thrust_error=0.08),
    Dispersions("misalignment-3", misalignment_deg=3.0),
    Dispersions("delay-2", delay_steps=2),
    Dispersions("nav-noise-2x", **_NAV2),
    Dispersions("gusts-4x", disturbance_scale=4.0),
    Dispersions("wide-box-40", box_widen=0.4),
    Dispersions(
        "all-broad",
        mass_kg=(1700.0, 2250.0),
        thrust_error=0.06,
        isp_error=0.06,
        misalignment_deg=3.0,
        delay_steps=1,
        disturbance_scale=4.0,
        box_widen=0.35,
        **{k: 1.5 * v for k, v in _NAV.items()},
    ),
)
SCENARIOS.update({d.name: d for d in BROAD_EXTRA})
# Training only (ours, issue 68): `broad` plus what a policy must adapt to rather than ride out,
# an engine weaker than commanded (one factor, from ignition or from a random time) and a
# constant navigation bias, alone and together. The judged `beyond` campaign (data/beyond.yaml)
# draws the same kinds on its own seeds.
ADAPT_EXTRA = (
    Dispersions("engine-weak", thrust_factor=(0.8, 1.0)),
    Dispersions("engine-weak-late", thrust_factor=(0.8, 1.0), thrust_factor_onset_s=(5.0, 40.0)),
    Dispersions("nav-bias-5", nav_position_bias_m=5.0, nav_velocity_bias_mps=0.2),
    Dispersions(
        "adapt-all",
        thrust_factor=(0.85, 1.0),
        thrust_factor_onset_s=(0.0, 30.0),
        nav_position_bias_m=3.0,
        nav_velocity_bias_mps=0.1,
        mass_kg=(1800.0, 2200.0),
        delay_steps=1,
        disturbance_scale=2.0,
    ),
)
SCENARIOS.update({d.name: d for d in ADAPT_EXTRA})
CAMPAIGNS = {
    "standard": STANDARD,
    "broad": STANDARD + tuple(d.name for d in BROAD_EXTRA),
    "adapt": STANDARD + tuple(d.name for d in BROAD_EXTRA + ADAPT_EXTRA),
}


def load_scenarios(spec: str) -> list[Dispersions]:
    """Scenarios of `spec`: a name of SCENARIOS, a comma-separated list of them, a campaign of
    CAMPAIGNS (`standard`: the ten judged scenarios; `broad`: those and harsher ones, for
    training; `adapt`: `broad` with a weak engine and a navigation bias) or a YAML file.

    YAML: either one scenario (a mapping of Dispersions fields) or `scenarios:` a list whose items
    are scenario names or mappings (a mapping with `base: <name>` starts from that scenario).
    """
    spec = spec.strip()
    if spec.endswith((".yaml", ".yml")) or Path(spec).is_file():
        return _from_yaml(Path(spec))
    names = list(CAMPAIGNS.get(spec, [s.strip() for s in spec.split(",") if s.strip()]))
    unknown = [n for n in names if n not in SCENARIOS]
    if unknown or not names:
        raise ValueError(
            f"unknown dispersion scenario(s) {unknown or [spec]}; choose from "
            f"{sorted(SCENARIOS)}, a campaign {sorted(CAMPAIGNS)} or a .yaml file"
        )
    return [SCENARIOS[n] for n in names]


def _from_yaml(path: Path) -> list[Dispersions]:
    import yaml  # PyYAML: only needed for scenario files

    try:
        doc = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise ValueError(f"{path}: cannot read dispersions: {exc}") from exc
    items = doc.get("scenarios") if isinstance(doc, dict) and "scenarios" in doc else [doc]
    if not isinstance(items, list) or not items:
        raise ValueError(f"{path}: expected a mapping or `scenarios:` with a list of them")
    out = []
    for k, item in enumerate(items):
        if isinstance(item, str):
            out.extend(load_scenarios(item))
            continue
        if not isinstance(item, dict):
            raise ValueError(f"{path}: scenario {k} is neither a name nor a mapping: {item!r}")
        item = dict(item)
        base = SCENARIOS[item.pop("base")].to_dict() if "base" in item else {}
        item.setdefault("name", f"{path.stem}-{k}" if len(items) > 1 else path.stem)
        out.append(Dispersions.from_dict({**base, **item}))
    return out


def failure_weights(failures: np.ndarray, episodes: np.ndarray, uniform_share: float) -> np.ndarray:
    """Probabilities of drawing each scenario in training: `uniform_share` spread evenly, the
    rest in proportion to each scenario's recent failure rate, Laplace-smoothed ((f+1)/(n+2),
    so a scenario not flown yet counts as 50 %). Domain randomisation then spends its episodes
    where the policy fails instead of where it already lands, and never stops visiting the
    others."""
    failures, episodes = np.asarray(failures, float), np.asarray(episodes, float)
    if failures.shape != episodes.shape or failures.ndim != 1 or not failures.size:
        raise ValueError("failures and episodes: one count per scenario")
    if not 0.0 <= uniform_share <= 1.0:
        raise ValueError(f"uniform_share must lie in [0, 1], got {uniform_share!r}")
    rate = (failures + 1.0) / (episodes + 2.0)
    k = failures.size
    return uniform_share / k + (1.0 - uniform_share) * rate / rate.sum()


# --- per-episode draws and the actuator model -------------------------------------------------


@dataclass
class EpisodeDraws:
    """What one episode of a scenario drew at reset."""

    mass_kg: float | None
    thrust_gain: np.ndarray  # (3,) delivered / commanded thrust per thruster
    isp_s: float
    rotation: np.ndarray  # (3, 3) misalignment of the delivered thrust
    nav_noise: np.ndarray | None  # (n_steps + 1, 7) added to the observed state, or None
    thrust_factor: float = 1.0  # one factor on every delivered thrust, from thrust_onset_step
    thrust_onset_step: int = 0  # first step (0.2 s) the factor acts on
    nav_bias: np.ndarray | None = None  # (7,) added to every observed state, or None
    wind_n: np.ndarray | None = None  # (3,) steady force, N, or None


def draw_episode(rng: np.random.Generator, d: Dispersions, n_steps: int) -> EpisodeDraws:
    """The fixed draws of a non-nominal scenario (see the module docstring for their order)."""
    u_mass = rng.uniform()
    u_thrust = rng.uniform(-1.0, 1.0, size=3)
    u_isp = rng.uniform(-1.0, 1.0)
    axis = rng.normal(size=3)
    u_angle = rng.uniform()
    nav_seed = int(rng.integers(0, 2**63 - 1))
    mass = None if d.mass_kg is None else d.mass_kg[0] + u_mass * (d.mass_kg[1] - d.mass_kg[0])
    angle = math.radians(d.misalignment_deg) * u_angle
    nav = None
    if d.has_nav_noise:
        nav = np.random.default_rng(nav_seed).normal(size=(n_steps + 1, STATE_DIM)) * d.nav_sigma
    out = EpisodeDraws(
        mass_kg=mass,
        thrust_gain=1.0 + d.thrust_error * u_thrust,
        isp_s=ISP_S * (1.0 + d.isp_error * u_isp),
        rotation=rotation_matrix(axis, angle),
        nav_noise=nav,
    )
    if d.has_issue68_parts:
        _draw_issue68(np.random.default_rng([nav_seed, 68]), d, out)
    return out


def _draw_issue68(rng: np.random.Generator, d: Dispersions, out: EpisodeDraws) -> None:
    """The thrust factor and its onset, the navigation bias and the wind of one episode, into
    out (always the same draws, in the order of the module's comment)."""
    u_factor, u_onset = rng.uniform(), rng.uniform()
    bias = []
    for _ in range(2):
        direction = rng.normal(size=3)
        bias.append(direction / np.linalg.norm(direction) * rng.uniform())
    heading = 2.0 * math.pi * rng.uniform()
    if d.thrust_factor is not None:
        lo, hi = d.thrust_factor
        out.thrust_factor = lo + u_factor * (hi - lo)
        if d.thrust_factor_onset_s is not None:
            t0, t1 = d.thrust_factor_onset_s
            out.thrust_onset_step = round((t0 + u_onset * (t1 - t0)) / DT_S)
    if d.has_nav_bias:
        out.nav_bias = np.concatenate(
            [bias[0] * d.nav_position_bias_m, bias[1] * d.nav_velocity_bias_mps, [0.0]]
        )
    if d.wind_force_n > 0.0:
        out.wind_n = d.wind_force_n * np.array([math.cos(heading), math.sin(heading), 0.0])


def rotation_matrix(axis: np.ndarray, angle_rad: float) -> np.ndarray:
    """Rodrigues' rotation (3, 3) by angle_rad about axis (any length; zero: identity)."""
    n = float(np.linalg.norm(axis))
    if n == 0.0 or angle_rad == 0.0:
        return np.eye(3)
    k = np.asarray(axis, dtype=float) / n
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle_rad) * kx + (1.0 - math.cos(angle_rad)) * (kx @ kx)


def delivered_thrust(
    command_n: np.ndarray, gain: np.ndarray, rotation: np.ndarray | None
) -> np.ndarray:
    """Thrust (N, 3) in N the plant delivers for commands (N, 3): per-thruster magnitude error
    `gain` (N, 3), then the misalignment `rotation` (N, 3, 3) of the delivered vector (or None)."""
    t = command_n * gain
    if rotation is None:
        return t
    return np.einsum("nij,nj->ni", rotation, t)


__all__ = [
    "CAMPAIGNS",
    "NOMINAL",
    "SCENARIOS",
    "Dispersions",
    "EpisodeDraws",
    "delivered_thrust",
    "draw_episode",
    "load_scenarios",
    "rotation_matrix",
]


class DispersionArrays:
    """What the episodes of N batched landers drew, and the plant model over them.

    Held by `PoweredDescentVectorEnv`; arrays are allocated only for parts some scenario uses.
    """

    def __init__(self, n: int, scenarios: tuple[Dispersions, ...], max_steps: int) -> None:
        self.scenario = np.zeros(n, dtype=np.int64)
        self.thrust_gain = np.ones((n, 3))
        self.isp_s = np.full(n, ISP_S)
        misaligned = any(d.misalignment_deg for d in scenarios)
        self.rotation = np.tile(np.eye(3), (n, 1, 1)) if misaligned else None
        self.delay_steps = np.zeros(n, dtype=np.int64)
        dmax = max(d.delay_steps for d in scenarios)
        self.fifo = np.zeros((n, dmax + 1, 3)) if dmax else None
        nav = any(d.has_nav_noise for d in scenarios)
        self.nav_noise = np.zeros((n, max_steps + 1, STATE_DIM)) if nav else None
        factor = any(d.thrust_factor is not None for d in scenarios)
        self.thrust_factor = np.ones(n) if factor else None
        self.thrust_onset_step = np.zeros(n, dtype=np.int64) if factor else None
        self.nav_bias = np.zeros((n, STATE_DIM)) if any(d.has_nav_bias for d in scenarios) else None
        self.wind_n = np.zeros((n, 3)) if any(d.wind_force_n > 0.0 for d in scenarios) else None

    def set_episode(self, i: int, k: int, d: Dispersions, dr: EpisodeDraws) -> None:
        """Lander i starts an episode of scenario k (= d) with draws dr."""
        self.scenario[i] = k
        self.thrust_gain[i] = dr.thrust_gain
        self.isp_s[i] = dr.isp_s
        if self.rotation is not None:
            self.rotation[i] = dr.rotation
        self.delay_steps[i] = d.delay_steps
        if self.fifo is not None:
            self.fifo[i] = 0.0
        if self.nav_noise is not None:
            self.nav_noise[i] = 0.0 if dr.nav_noise is None else dr.nav_noise
        if self.thrust_factor is not None:
            self.thrust_factor[i] = dr.thrust_factor
            self.thrust_onset_step[i] = dr.thrust_onset_step
        if self.nav_bias is not None:
            self.nav_bias[i] = 0.0 if dr.nav_bias is None else dr.nav_bias
        if self.wind_n is not None:
            self.wind_n[i] = 0.0 if dr.wind_n is None else dr.wind_n

    def plant(
        self, idx: np.ndarray | slice, command_n: np.ndarray, steps: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """(delivered thrust (M, 3) in N, specific impulse (M,) in s) of landers idx this step
        (`steps` (M,): steps flown so far, for the thrust factor's onset): the command enters the
        FIFO, the delayed command leaves it and goes through the errors."""
        applied = command_n
        if self.fifo is not None:
            fifo = np.concatenate([command_n[:, None], self.fifo[idx][:, :-1]], axis=1)
            self.fifo[idx] = fifo
            applied = fifo[np.arange(len(fifo)), self.delay_steps[idx]]
        rot = None if self.rotation is None else self.rotation[idx]
        gain = self.thrust_gain[idx]
        if self.thrust_factor is not None:
            if steps is None:
                raise ValueError("plant: a thrust factor needs the steps flown")
            on = steps >= self.thrust_onset_step[idx]
            gain = gain * np.where(on, self.thrust_factor[idx], 1.0)[:, None]
        return delivered_thrust(applied, gain, rot), self.isp_s[idx]

    def wind(self, idx: np.ndarray | slice) -> np.ndarray | None:
        """The steady force (M, 3) in N on landers idx, or None where no scenario has wind."""
        return None if self.wind_n is None else self.wind_n[idx]

    def observed(self, states: np.ndarray, steps: np.ndarray) -> np.ndarray:
        """What the agent observes of true states (N, 7) after `steps` steps."""
        out = states.copy() if self.nav_noise is None else None
        if self.nav_noise is not None:
            k = np.minimum(steps, self.nav_noise.shape[1] - 1)
            out = states + self.nav_noise[np.arange(len(states)), k]
        if self.nav_bias is not None:
            out += self.nav_bias
        return out

    def state_dict(self) -> dict[str, np.ndarray]:
        return {k: v.copy() for k, v in vars(self).items() if v is not None}

    def load_state_dict(self, d: dict[str, Any]) -> None:
        for k, v in vars(self).items():
            if v is not None and k in d:
                v[...] = np.asarray(d[k])
