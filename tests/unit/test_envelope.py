"""The braking law has one home (`pd_core.envelope`): the constant-mass limit is, to the bit, the
formula every file before issue 68 flew; the mass-loss limit is the speed from which a burn at
the margin force, its mass falling by the rocket equation, reaches the land speed at the pad;
the layer's compiled rule, the teacher and the Python functions are the same law; and a policy
file that does not name the new settings flies as it did."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from pd_core import envelope
from pd_core.config import BRAKE_MARGIN, DT_S, LAND_SPEED_MPS, TOUCHDOWN_SPEED_MPS
from pd_core.runtime import kernels_rules
from pd_core.runtime.config import ADDED_FIELDS, RulesConfig, RuntimeConfig
from pd_core.runtime.decision import LIMITS
from pd_core.runtime.policy_file import load_policy
from pd_core.runtime.rules import _ANY_SPACE as SPACE
from pd_core.runtime.rules import brake_mask, max_descent_speed_mps, rule_settings
from pd_core.teachers.mpc import brake_limited
from pd_core.vector_env import make_vector_env

G = 3.72
T_MAX_N = 13e3
F = BRAKE_MARGIN * T_MAX_N  # the braking force the layer counts on at full measured thrust
MODELS = Path(__file__).resolve().parents[2] / "models"


def _random_states(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    s = np.zeros((n, 7))
    s[:, 2] = rng.uniform(-1.0, 3000.0, n)
    s[:, 5] = rng.uniform(-110.0, 5.0, n)
    s[:, 6] = rng.uniform(1100.0, 3000.0, n)
    return s


def test_the_constant_mass_limit_is_the_historic_formula_to_the_bit():
    s = _random_states(4000)
    z, m = s[:, 2], s[:, 6]
    f = np.random.default_rng(1).uniform(0.5, 1.0, len(z)) * T_MAX_N
    # the layer's own formula before issue 68 (pd_core.runtime.kernels_rules.max_descent_speed)
    historic = [
        math.sqrt(LAND_SPEED_MPS**2 + 2.0 * max(BRAKE_MARGIN * t / mi - G, 0.0) * max(zi, 0.0))
        for zi, mi, t in zip(z, m, f, strict=True)
    ]
    python = [
        envelope.max_descent_speed_mps(zi, mi, BRAKE_MARGIN * t, LAND_SPEED_MPS, G)
        for zi, mi, t in zip(z, m, f, strict=True)
    ]
    compiled = max_descent_speed_mps(z, m, f, RulesConfig())
    assert python == historic
    np.testing.assert_array_equal(compiled, historic)


def test_the_mass_loss_limit_is_the_burn_that_reaches_the_land_speed_at_the_pad():
    """Integrate the burn from (z, -v_max) at force F, mass falling at F / v_e: it slows to the
    land speed at the ground, within a millimetre."""
    v_e = envelope.EXHAUST_VELOCITY_MPS
    for z0, m0 in ((2500.0, 2000.0), (800.0, 2300.0), (40.0, 1500.0), (2600.0, 2450.0)):
        v0 = envelope.max_descent_speed_mass_loss_mps(z0, m0, F, LAND_SPEED_MPS, G)

        def rhs(_t, y):
            return [y[1], F / y[2] - G, -F / v_e]

        def slowed(_t, y):
            return y[1] + LAND_SPEED_MPS

        slowed.terminal = True
        sol = solve_ivp(rhs, (0, 500), [z0, -v0, m0], events=slowed, rtol=1e-12, atol=1e-10)
        assert sol.status == 1 and abs(sol.y_events[0][0][0]) < 1e-3, (z0, m0, sol.y_events)
        assert v0 > envelope.max_descent_speed_mps(z0, m0, F, LAND_SPEED_MPS, G)


def test_the_mass_loss_limit_gains_what_the_fuel_burnt_is_worth():
    """At 2500 m the limit rises from 103.2 to 109.4 m/s for 2000 kg (6 %) and from 82.7 to
    89.7 m/s for 2300 kg (8.5 %: the heavier lander's net deceleration is smaller, so the same
    mass flow is worth more of it); it equals the constant-mass limit where the lander cannot
    brake, at the pad, or where the burn would run it dry."""
    for m, const_mps, loss_mps in ((2000.0, 103.20, 109.39), (2300.0, 82.67, 89.67)):
        const = envelope.max_descent_speed_mps(2500.0, m, F, LAND_SPEED_MPS, G)
        loss = envelope.max_descent_speed_mass_loss_mps(2500.0, m, F, LAND_SPEED_MPS, G)
        assert const == pytest.approx(const_mps, abs=0.01)
        assert loss == pytest.approx(loss_mps, abs=0.01)
    for z, m in ((1000.0, 3200.0), (0.0, 2000.0), (-3.0, 2000.0)):
        assert envelope.max_descent_speed_mass_loss_mps(
            z, m, F, LAND_SPEED_MPS, G
        ) == envelope.max_descent_speed_mps(z, m, F, LAND_SPEED_MPS, G)
    dry = envelope.max_descent_speed_mass_loss_mps(2500.0, 1050.0, F, LAND_SPEED_MPS, G)
    assert dry == envelope.max_descent_speed_mps(2500.0, 1050.0, F, LAND_SPEED_MPS, G)


@pytest.mark.parametrize("mass_loss", [False, True])
def test_the_layer_the_teacher_and_python_fire_the_same_limit(mass_loss):
    s = _random_states(3000, seed=2)
    t_z = np.random.default_rng(3).uniform(0.0, T_MAX_N, len(s))
    p = RulesConfig(brake_mass_loss=mass_loss)
    rp = rule_settings(p, SPACE).params
    layer = [kernels_rules.brake_limit_row(s[i], t_z[i], T_MAX_N, rp) for i in range(len(s))]
    python = [
        envelope.brake_fires(
            s[i, 2], s[i, 5], s[i, 6], BRAKE_MARGIN * t_z[i], F, LAND_SPEED_MPS,
            TOUCHDOWN_SPEED_MPS, G, DT_S, mass_loss,
        )
        for i in range(len(s))
    ]  # fmt: skip
    teacher = [brake_limited(s[i], t_z[i], T_MAX_N, mass_loss=mass_loss) for i in range(len(s))]
    assert layer == python
    np.testing.assert_array_equal(np.array(layer) != 0, teacher)
    np.testing.assert_array_equal(brake_mask(s, t_z, T_MAX_N, p), teacher)
    fired = {LIMITS[k] for k in layer}
    want = "descent-mass-loss" if mass_loss else "descent"
    assert fired == {"none", want, "touchdown"}
    compiled = max_descent_speed_mps(s[:, 2], s[:, 6], np.full(len(s), T_MAX_N), p)
    py = [
        envelope.max_descent_speed_for(z, m, F, LAND_SPEED_MPS, G, mass_loss)
        for z, m in zip(s[:, 2], s[:, 6], strict=True)
    ]
    np.testing.assert_allclose(compiled, py, rtol=1e-14)


def test_a_file_without_the_new_settings_flies_the_historic_values():
    meta = json.loads((MODELS / "pd_dqn_ocp.json").read_text())
    runtime = meta["runtime"]
    for part, added in ADDED_FIELDS.items():
        assert not set(added) & set(runtime[part])  # shipped before issue 68
    cfg = RuntimeConfig.from_dict(runtime)
    assert cfg.rules.brake_mass_loss is False and cfg.latency.unmeasured_thrust == 1.0
    assert load_policy(MODELS / "pd_dqn_ocp.pt").config == cfg
    again = RuntimeConfig.from_dict(json.loads(json.dumps(cfg.to_dict())))
    assert again == cfg and "brake_mass_loss" in cfg.to_dict()["rules"]
    with pytest.raises(ValueError, match="unknown"):
        RuntimeConfig.from_dict({**runtime, "rules": {**runtime["rules"], "brake_mass": 1}})


def test_each_option_changes_the_flight_and_the_record_says_which_limit_fired():
    """64 `engine80-100` landers of the shipped file, 40 s: the default fires the constant-mass
    limit only; with the mass-loss limit that one only, and the layer brakes on fewer steps;
    counting on the weakest engine until measured, the fraction counted on starts at 0.8."""
    rt0 = load_policy(MODELS / "pd_dqn_ocp.pt")
    runs = {}
    for name, settings in (
        ("default", ""),
        ("mass-loss", "brake_mass_loss=1"),
        ("weakest", "unmeasured_thrust=0.8"),
    ):
        rt = load_policy(MODELS / "pd_dqn_ocp.pt")
        rt = type(rt)(rt.actor, rt0.config.with_settings(settings), rt.actions, rt.name)
        env = make_vector_env(
            64, autoreset=False, dispersions=str(Path(MODELS.parent, "data", "beyond.yaml"))
        )
        _, info = env.reset(seed=68_000_000)
        rt.begin_episodes(64)
        limits, first_frac = np.zeros(len(LIMITS), dtype=int), None
        for _ in range(200):
            act, d = rt.step_rows(info["observed_state"], np.arange(64))
            first_frac = d.thrust_gain_bound.copy() if first_frac is None else first_frac
            limits += np.bincount(d.brake_limit, minlength=len(LIMITS))
            _, _, _, _, info = env.step(act)
        runs[name] = (limits, first_frac, rt.counts["brake"])
    assert runs["default"][0][2] == 0 and runs["default"][0][1] > 0
    assert runs["mass-loss"][0][1] == 0 and runs["mass-loss"][0][2] > 0
    assert runs["mass-loss"][2] < runs["default"][2]
    assert np.all(runs["default"][1] == 1.0) and np.all(runs["weakest"][1] == 0.8)
    assert runs["weakest"][2] > runs["default"][2]


def test_the_limits_slope_is_what_an_optimiser_linearises():
    z = np.array([0.0, 5.0, 300.0, 2500.0])
    m = np.array([2000.0, 1900.0, 2100.0, 2300.0])
    for mass_loss in (False, True):
        v, slope = envelope.descent_limits(z, m, F, LAND_SPEED_MPS, G, mass_loss)
        want = [envelope.max_descent_speed_for(a, b, F, LAND_SPEED_MPS, G, mass_loss)
                for a, b in zip(z, m, strict=True)]  # fmt: skip
        np.testing.assert_allclose(v, want, rtol=1e-15)
        up, _ = envelope.descent_limits(z[1:] + 0.1, m[1:], F, LAND_SPEED_MPS, G, mass_loss)
        down, _ = envelope.descent_limits(z[1:] - 0.1, m[1:], F, LAND_SPEED_MPS, G, mass_loss)
        np.testing.assert_allclose(slope[1:], (up - down) / 0.2, rtol=1e-4)
        assert slope[0] == 0.0
