"""Eqs. 1-3: free fall, mass depletion, hover, and the exact constant-thrust solution."""

import math

import numpy as np
import pytest

from pd_core import dynamics
from pd_core.config import DT_S, G0_MPS2, GRAVITY_MPS2, ISP_S

S0 = np.array([600.0, -200.0, 2500.0, -40.0, 10.0, -80.0, 2000.0])


def run(state, thrust, n, force=(0.0, 0.0, 0.0)):
    for _ in range(n):
        state = dynamics.step(state, np.asarray(thrust, float), np.asarray(force, float), DT_S)
    return state


def test_free_fall_matches_closed_form():
    t = 100 * DT_S
    s = run(S0, (0.0, 0.0, 0.0), 100)
    expected_pos = S0[:3] + S0[3:6] * t + 0.5 * GRAVITY_MPS2 * t**2
    np.testing.assert_allclose(s[:3], expected_pos, rtol=0, atol=1e-9)
    np.testing.assert_allclose(s[3:6], S0[3:6] + GRAVITY_MPS2 * t, rtol=0, atol=1e-11)
    assert s[6] == S0[6]


def test_constant_thrust_depletes_mass_as_eq3():
    thrust = np.array([3000.0, -2000.0, 9000.0])
    s = run(S0, thrust, 50)
    expected = S0[6] - (3000 + 2000 + 9000) / (ISP_S * G0_MPS2) * 50 * DT_S
    assert s[6] == pytest.approx(expected, rel=0, abs=1e-9)


def test_constant_thrust_matches_rocket_equation():
    """Many dt steps equal the closed-form solution of Eq. 2 with linearly falling mass."""
    thrust = np.array([3000.0, -2000.0, 9000.0])
    n = 150
    t = n * DT_S
    mdot = np.abs(thrust).sum() / (ISP_S * G0_MPS2)
    w = 1 - mdot * t / S0[6]
    dv = -(thrust / mdot) * math.log(w)
    dx = (thrust * S0[6] / mdot**2) * (1 - w + w * math.log(w))
    s = run(S0, thrust, n)
    np.testing.assert_allclose(s[3:6], S0[3:6] + GRAVITY_MPS2 * t + dv, atol=1e-9)
    np.testing.assert_allclose(
        s[:3], S0[:3] + S0[3:6] * t + 0.5 * GRAVITY_MPS2 * t**2 + dx, atol=1e-7
    )


def test_thrust_equal_to_weight_holds_altitude():
    s = S0.copy()
    s[3:6] = 0.0
    for _ in range(50):  # 10 s, thrust re-set to the current weight every step
        s = dynamics.step(s, np.array([0.0, 0.0, -GRAVITY_MPS2[2] * s[6]]), np.zeros(3), DT_S)
    # Only the mass burnt within each 0.2 s step makes the lander climb: ~3 cm in 10 s.
    assert abs(s[2] - S0[2]) < 0.05
    assert abs(s[5]) < 0.01
    np.testing.assert_array_equal(s[:2], S0[:2])


def test_disturbance_force_enters_like_thrust():
    f = np.array([100.0, -50.0, 20.0])
    a = dynamics.step(S0, np.array([1000.0, 0.0, 5000.0]), f, DT_S)
    b = dynamics.step(S0, np.array([1100.0, -50.0, 5020.0]), np.zeros(3), DT_S)
    np.testing.assert_allclose(a[:6], b[:6], atol=1e-12)
    assert a[6] > b[6]  # the disturbance costs no fuel


def test_batched_equals_single_and_scalar():
    rng = np.random.default_rng(0)
    states = S0 + rng.normal(0, [100, 100, 100, 10, 10, 10, 50], size=(64, 7))
    thrust = rng.uniform([-1e4, -1e4, 0], [1e4, 1e4, 1.3e4], size=(64, 3))
    force = rng.normal(0, 100, size=(64, 3))
    batched = dynamics.step(states, thrust, force, DT_S)
    for i in range(64):
        np.testing.assert_allclose(dynamics.step(states[i], thrust[i], force[i], DT_S), batched[i])
        scalar = dynamics.step_scalar(tuple(states[i]), tuple(thrust[i]), tuple(force[i]), DT_S)
        np.testing.assert_allclose(np.array(scalar), batched[i], rtol=1e-13, atol=1e-10)


def test_engines_stop_at_dry_mass():
    s = S0.copy()
    s[6] = dynamics.DRY_MASS_KG + 1.0  # 1 kg of fuel left, full thrust burns ~3 kg per step
    s1 = dynamics.step(s, np.array([1e4, 1e4, 1.3e4]), np.zeros(3), DT_S)
    assert s1[6] == pytest.approx(dynamics.DRY_MASS_KG, abs=1e-9)
    s2 = dynamics.step(s1, np.array([1e4, 1e4, 1.3e4]), np.zeros(3), DT_S)
    np.testing.assert_allclose(s2[3:6], s1[3:6] + GRAVITY_MPS2 * DT_S, atol=1e-12)
    assert s2[6] == s1[6]
