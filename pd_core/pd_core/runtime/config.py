"""`RuntimeConfig`: every tunable of the runtime layer, typed, pinned whole in the policy file.

Four parts, one per component of `pd_core.runtime.layer.Runtime`:
- `RulesConfig`: the braking limit, the touchdown guard and the handover (`pd_core.runtime.rules`);
- `LatencyConfig`: the delay and thrust identification and the prediction through the queued
  commands (`pd_core.runtime.latency`);
- `NavFilterConfig`: the navigation filter (`pd_core.runtime.navfilter`);
- `fallback`: the gains of the ZEM/ZEV-vernier law flown at a handover (`ZemZevParams`).

The defaults are what the shipped policy flies; `RuntimeConfig.off()` is the bare network (no
rule, no prediction, no filter). `to_dict` writes every field; `from_dict` needs every field, so a
file never takes a behaviour default from code, except the fields added after a file could have
been written without them (`ADDED_FIELDS`): a file without one flies the value the code flew
before the field existed. The evidence behind each default is in
`docs/experiments/runtime-layer-history.md`.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from dataclasses import dataclass, field, fields, replace
from typing import Any

from pd_core.config import (
    BRAKE_MARGIN,
    GUARD_ALTITUDE_M,
    GUARD_CLIMB_MPS2,
    HANDOVER_ALTITUDE_M,
    HANDOVER_MASS_KG,
    LAND_SPEED_MPS,
    MAX_DELAY_STEPS,
    TOUCHDOWN_SPEED_MPS,
)
from pd_core.teachers.zemzev import VERNIER_PARAMS, ZemZevParams

NETWORK_DTYPES = ("float32", "float64")


def _check(ok: bool, name: str, value: Any, allowed: str) -> None:
    if not ok:
        raise ValueError(f"runtime setting {name} must be {allowed}, got {value!r}")


@dataclass(frozen=True)
class RulesConfig:
    """The three rules between the network and the thrusters (`pd_core.runtime.rules`)."""

    enabled: bool = True
    """False: no rule ever changes an action"""
    thrust_margin: float = BRAKE_MARGIN
    """fraction of full vertical thrust the braking limit counts on"""
    land_speed_mps: float = LAND_SPEED_MPS
    """descent speed the braking limit brakes to at the pad"""
    touchdown_speed_mps: float = TOUCHDOWN_SPEED_MPS
    """a step that ends on the ground fires the braking limit only above this touchdown speed
    (0: the limit holds below the pad too)"""
    measured_thrust: bool = True
    """the braking limit counts on the vertical thrust the latency stage measured, where short"""
    min_measured_thrust: float = 0.5
    """floor of the measured thrust fraction counted on (a guard against a nonsense estimate)"""
    guard_altitude_m: float = GUARD_ALTITUDE_M
    """below this observed altitude a descending lander may not free-fall (0: no guard)"""
    guard_climb_mps2: float = GUARD_CLIMB_MPS2
    """where the guard's raised level climbs faster than this, only a descent faster than the
    land speed counts as free fall"""
    handover_altitude_m: float = HANDOVER_ALTITUDE_M
    """above this observed altitude the fallback flies where its lateral limit binds (0: never)"""
    handover_mass_kg: float = HANDOVER_MASS_KG
    """below this observed mass the fallback flies (0: never)"""
    brake_mass_loss: bool = False
    """the braking limit counts on the mass lost while braking (the rocket equation at the
    margin thrust, `pd_core.envelope`); False: on the mass now, as every file before issue 68"""

    def __post_init__(self) -> None:
        _check(0.0 < self.thrust_margin <= 1.0, "thrust_margin", self.thrust_margin, "in (0, 1]")
        _check(0.0 <= self.land_speed_mps < 2.0, "land_speed_mps", self.land_speed_mps, "in [0, 2)")
        t = self.touchdown_speed_mps
        _check(t == 0.0 or 0.1 <= t < 2.0, "touchdown_speed_mps", t, "0 or in [0.1, 2)")
        m = self.min_measured_thrust
        _check(0.0 < m <= 1.0, "min_measured_thrust", m, "in (0, 1]")
        g = self.guard_altitude_m
        _check(0.0 <= g <= 1000.0, "guard_altitude_m", g, "in [0, 1000]")
        _check(self.guard_climb_mps2 >= 0.0, "guard_climb_mps2", self.guard_climb_mps2, ">= 0")
        h = self.handover_altitude_m
        _check(0.0 <= h <= 3000.0, "handover_altitude_m", h, "in [0, 3000]")
        k = self.handover_mass_kg
        _check(0.0 <= k <= 3000.0, "handover_mass_kg", k, "in [0, 3000]")


@dataclass(frozen=True)
class LatencyConfig:
    """Delay and thrust identification, prediction through the queued commands
    (`pd_core.runtime.latency`)."""

    max_delay_steps: int = MAX_DELAY_STEPS
    """longest actuation delay (0.2 s steps) identified and predicted through (0: none)"""
    thrust_model: bool = True
    """identify a thrust matrix per lag (else the nominal plant)"""
    forget_per_step: float = 0.97
    """weight of a residual one step older in the lag scores and the force noise"""
    switch_margin_mps2: float = 0.3
    """(m/s)^2 by which another lag's score must win for the estimate to move"""
    tie_break_mps2: float = 1e-3
    """(m/s)^2 added per step of lag to the initial score: ties go to the shorter lag"""
    thrust_matrix_prior_sd: float = 0.1
    """prior spread of each entry of the thrust matrix"""
    force_noise_n: float = 1000.0
    """prior spread of one step's measured force per axis (N)"""
    shortfall_sd: float = 3.0
    """standard deviations added to the identified vertical gain before the rules count on it"""
    window_steps: int = 5
    """steps over which the vertical gain is also measured from the whole velocity change"""
    window_forget: float = 0.9
    """weight of a window one window older"""
    window_noise_mps: float = 0.5
    """prior spread of one window's velocity-change residual (m/s)"""
    window_min_evidence: float = 25.0
    """(m/s)^2 of commanded vertical velocity change before the window measure is used"""
    jump_m: float = 50.0
    """a row whose position jumps this far from where it was heading starts a new episode"""
    unmeasured_thrust: float = 1.0
    """delivered fraction of the vertical thrust the rules count on until the engine has been
    measured in flight (1: nominal, as every file before issue 68; 0.8: the weakest engine
    promised); needs `thrust_model`"""
    measured_gain_sd: float = 0.02
    """the engine counts as measured once the vertical gain of the lag flown is known to this
    standard deviation"""

    def __post_init__(self) -> None:
        d = self.max_delay_steps
        _check(isinstance(d, int) and 0 <= d <= 10, "max_delay_steps", d, "an integer in [0, 10]")
        for name in ("forget_per_step", "window_forget"):
            v = getattr(self, name)
            _check(0.0 < v < 1.0, name, v, "in (0, 1)")
        w = self.window_steps
        _check(isinstance(w, int) and w >= 1, "window_steps", w, "an integer >= 1")
        for name in (
            "switch_margin_mps2",
            "tie_break_mps2",
            "shortfall_sd",
            "window_min_evidence",
        ):
            _check(getattr(self, name) >= 0.0, name, getattr(self, name), ">= 0")
        for name in (
            "thrust_matrix_prior_sd",
            "force_noise_n",
            "window_noise_mps",
            "jump_m",
            "measured_gain_sd",
        ):
            _check(getattr(self, name) > 0.0, name, getattr(self, name), "> 0")
        u = self.unmeasured_thrust
        _check(0.0 < u <= 1.0, "unmeasured_thrust", u, "in (0, 1]")


@dataclass(frozen=True)
class NavFilterConfig:
    """The navigation filter (`pd_core.runtime.navfilter`)."""

    enabled: bool = True
    """decide on the filter's estimate where the navigation is noisy (else the observation)"""
    position_floor_m: float = 0.3
    """position noise per axis below which the observation is flown as it is"""
    velocity_floor_mps: float = 0.03
    """velocity noise per axis below which the observation is flown as it is"""
    unmodelled_accel_mps2: float = 0.3
    """white acceleration the model lacks, per axis (gusts)"""
    bias_walk_mps2: float = 0.2
    """per-step change of the unmodelled steady acceleration"""
    forget_per_step: float = 0.97
    """weight of a one-step-older sample in the noise estimate"""
    warm_steps: int = 10
    """steps of evidence before the estimate may replace the observation"""
    prior_noise_m: float = 4.0
    """position noise assumed during the warm-up (m)"""
    prior_noise_mps: float = 0.4
    """velocity noise assumed during the warm-up (m/s)"""
    initial_sd_m: float = 5.0
    """prior spread of a new lander's position (m)"""
    initial_sd_mps: float = 0.5
    """prior spread of a new lander's velocity (m/s)"""
    initial_sd_mps2: float = 1.0
    """prior spread of a new lander's unmodelled acceleration (m/s^2)"""

    def __post_init__(self) -> None:
        _check(0.0 < self.forget_per_step < 1.0, "forget_per_step", self.forget_per_step, "(0, 1)")
        w = self.warm_steps
        _check(isinstance(w, int) and w >= 2, "warm_steps", w, "an integer >= 2")
        for f in fields(self):
            if f.type == "float" and f.name != "forget_per_step":
                v = getattr(self, f.name)
                _check(v > 0.0 or "walk" in f.name, f.name, v, "> 0")


@dataclass(frozen=True)
class RuntimeConfig:
    """Everything that decides what the runtime layer does; see the module docstring."""

    rules: RulesConfig = field(default_factory=RulesConfig)
    latency: LatencyConfig = field(default_factory=LatencyConfig)
    nav_filter: NavFilterConfig = field(default_factory=NavFilterConfig)
    fallback: ZemZevParams = VERNIER_PARAMS
    network_dtype: str = "float32"
    """arithmetic of the network's forward pass ("float32" or "float64")"""

    def __post_init__(self) -> None:
        d = self.network_dtype
        _check(d in NETWORK_DTYPES, "network_dtype", d, " or ".join(NETWORK_DTYPES))

    @classmethod
    def off(cls, network_dtype: str = "float32") -> RuntimeConfig:
        """The bare network: no rule, no prediction, no filter."""
        return cls(
            rules=RulesConfig(enabled=False),
            latency=LatencyConfig(max_delay_steps=0),
            nav_filter=NavFilterConfig(enabled=False),
            network_dtype=network_dtype,
        )

    @property
    def is_off(self) -> bool:
        """True where the layer never changes an action nor the state decided on."""
        return (
            not self.rules.enabled
            and self.latency.max_delay_steps == 0
            and not self.nav_filter.enabled
        )

    def to_dict(self) -> dict[str, Any]:
        """Every field, nested by part (JSON-ready)."""
        return dataclasses.asdict(self)

    def digest(self) -> str:
        """12 hex digits of the SHA-256 of `to_dict` as sorted JSON: names this config in logs
        and `/diagnostics`."""
        text = json.dumps(self.to_dict(), sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()[:12]

    @classmethod
    def from_dict(cls, d: Any) -> RuntimeConfig:
        """The config of `to_dict`'s form; ValueError naming any missing, unknown or bad field."""
        parts = {
            "rules": RulesConfig,
            "latency": LatencyConfig,
            "nav_filter": NavFilterConfig,
            "fallback": ZemZevParams,
        }
        _exact_keys(d, [*parts, "network_dtype"], "runtime")
        built = {
            name: _build(kind, {**ADDED_FIELDS.get(name, {}), **_object(d[name], name)}, name)
            for name, kind in parts.items()
        }
        return cls(**built, network_dtype=str(d["network_dtype"]))

    def with_settings(self, settings: str) -> RuntimeConfig:
        """This config with "KEY=VALUE,KEY=VALUE" changed; a KEY is `part.field` or a field name
        found in one part only (`thrust_margin`, `max_delay_steps`, ...). ValueError in one line."""
        out = self
        for item in filter(None, (s.strip() for s in settings.split(","))):
            key, eq, value = item.partition("=")
            if not eq:
                raise ValueError(f"runtime settings {settings!r}: {item!r} is not KEY=VALUE")
            out = out._with_one(key.strip(), value.strip(), settings)
        return out

    def _with_one(self, key: str, value: str, settings: str) -> RuntimeConfig:
        part, _, name = key.rpartition(".")
        if not part and name == "nav_filter":  # the filter on or off, as in format 1
            part, name = "nav_filter", "enabled"
        owners = [
            p for p in ("rules", "latency", "nav_filter", "fallback") if not part or p == part
        ]
        owners = [p for p in owners if name in _field_types(type(getattr(self, p)))]
        if name == "network_dtype" and not part:
            return replace(self, network_dtype=value)
        if len(owners) != 1:
            why = "unknown" if not owners else f"ambiguous ({', '.join(owners)})"
            raise ValueError(f"runtime settings {settings!r}: {key!r} is {why}")
        sub = getattr(self, owners[0])
        try:
            new = replace(sub, **{name: _parse(_field_types(type(sub))[name], value, key)})
        except (TypeError, ValueError) as exc:
            raise ValueError(f"runtime settings {settings!r}: {exc}") from None
        return replace(self, **{owners[0]: new})


ADDED_FIELDS: dict[str, dict[str, Any]] = {
    "rules": {"brake_mass_loss": False},
    "latency": {"unmeasured_thrust": 1.0, "measured_gain_sd": 0.02},
}
"""fields added after policy files were shipped (issue 68), by part, with the value every file
written before them flies"""


def _field_types(kind: type) -> dict[str, str]:
    return {f.name: str(f.type) for f in fields(kind)}


def _parse(type_name: str, value: Any, name: str) -> Any:
    """A field's value from JSON or from a KEY=VALUE string, of the field's declared type."""
    if type_name == "bool":
        if isinstance(value, bool):
            return value
        if str(value).lower() in ("1", "1.0", "true"):
            return True
        if str(value).lower() in ("0", "0.0", "false"):
            return False
        raise ValueError(f"{name} must be true or false (1 or 0), got {value!r}")
    if type_name == "int":
        f = float(value)
        if f != int(f):
            raise ValueError(f"{name} must be an integer, got {value!r}")
        return int(f)
    if type_name == "float":
        return float(value)
    raise ValueError(f"{name}: unsupported field type {type_name}")


def _object(d: Any, where: str) -> dict[str, Any]:
    if not isinstance(d, dict):
        raise ValueError(f"{where} settings must be an object, got {type(d).__name__}")
    return d


def _exact_keys(d: Any, want: list[str], where: str) -> None:
    if not isinstance(d, dict):
        raise ValueError(f"{where} settings must be an object, got {type(d).__name__}")
    missing = [k for k in want if k not in d]
    unknown = sorted(set(d) - set(want))
    if missing or unknown:
        raise ValueError(f"{where} settings: missing {missing}, unknown {unknown}")


def _build(kind: type, d: Any, where: str) -> Any:
    types = _field_types(kind)
    _exact_keys(d, list(types), where)
    return kind(**{k: _parse(t, d[k], f"{where}.{k}") for k, t in types.items()})
