"""Eqs. 12-18 at hand-computed states, both altitude branches, and the t_go guards."""

import math
from dataclasses import replace

import numpy as np
import pytest

from pd_core.config import REWARD
from pd_core.reward import landed, reward, reward_scalar, target_velocity


def r(pos, vel, thrust):
    return float(reward(np.array(pos, float), np.array(vel, float), np.array(thrust, float)))


def test_above_15m_straight_descent():
    # r_hat = (0,0,100), v_hat = (0,0,-10), t_go = 10 s, tau = 20 s
    target_z = -70 * (1 - math.exp(-0.5))  # -27.5428538 m/s
    expected = -0.01 * abs(-12 - target_z) - 0.05 * 0.5 + 0.01
    assert expected == pytest.approx(-0.1704285382011566, abs=1e-15)
    assert r([0, 0, 115], [0, 0, -12], [0, 0, 6500]) == pytest.approx(expected, abs=1e-12)


def test_above_15m_with_crossrange():
    # r_hat = (300, 0, 400), |r_hat| = 500; v_hat = (-30, 0, -38)
    t_go = 500 / math.sqrt(30**2 + 38**2)
    gain = 70 * (1 - math.exp(-t_go / 20)) / 500
    target = (-gain * 300, 0.0, -gain * 400)
    err = math.sqrt((-30 - target[0]) ** 2 + (-40 - target[2]) ** 2)
    effort = math.sqrt(0.5**2 + 0.2**2 + (6500 / 13000) ** 2)
    expected = -0.01 * err - 0.05 * effort + 0.01
    got = r([300, 0, 415], [-30, 0, -40], [5000, -2000, 6500])
    assert got == pytest.approx(expected, abs=1e-12)
    np.testing.assert_allclose(
        target_velocity(np.array([300.0, 0, 415]), np.array([-30.0, 0, -40])), target, atol=1e-12
    )


def test_below_15m_branch_targets_vertical_descent():
    # r_hat = (0,0,10) ignores the 3-4 m offset; v_hat = v - (0,0,-1) = (0,0,-2)
    # t_go = 5 s, tau = 100 s
    target_z = -70 * (1 - math.exp(-0.05))  # -3.41394 m/s
    expected = -0.01 * abs(-3 - target_z) - 0.05 * math.sqrt(3) + 0.01
    assert expected == pytest.approx(-0.08074194322794306, abs=1e-14)
    assert r([3, 4, 10], [0, 0, -3], [10000, -10000, 13000]) == pytest.approx(expected, abs=1e-12)


def test_landing_bonus_kappa():
    # z < 0.01, |x| = 1.414 < 5, |v| = 1.118 < 2: kappa = 10 on top of the shaping terms
    t_go = 0.005 / 0.5
    tz = -70 * (1 - math.exp(-t_go / 100))
    err = math.sqrt(0.5**2 + (-1 - tz) ** 2)
    expected = -0.01 * err + 0.01 + 10.0
    assert r([1, 1, 0.005], [0.5, 0, -1], [0, 0, 0]) == pytest.approx(expected, abs=1e-12)
    assert not landed(np.array([1, 1, 0.005]), np.array([0.5, 0, -2.5]))
    assert not landed(np.array([6, 0, 0.005]), np.array([0.5, 0, -1]))
    assert not landed(np.array([1, 1, 0.02]), np.array([0.5, 0, -1]))


def test_zero_relative_speed_is_finite():
    # v_hat = 0 above 15 m: t_go -> inf, target saturates at v0 towards r_hat
    tv = target_velocity(np.array([0.0, 0.0, 115.0]), np.array([0.0, 0.0, -2.0]))
    np.testing.assert_allclose(tv, [0, 0, -70], atol=1e-9)
    # on the pad (r_hat = 0) the target is 0, not NaN
    tv = target_velocity(np.array([0.0, 0.0, 0.0]), np.array([0.0, 0.0, -1.0]))
    np.testing.assert_array_equal(tv, [0, 0, 0])


def test_batched_equals_scalar():
    rng = np.random.default_rng(0)
    pos = rng.uniform([-1000, -1000, -1], [1000, 1000, 2600], size=(200, 3))
    pos[:50, 2] = rng.uniform(-0.5, 16, 50)
    vel = rng.normal(0, 30, size=(200, 3))
    thrust = rng.uniform([-1e4, -1e4, 0], [1e4, 1e4, 1.3e4], size=(200, 3))
    batched = reward(pos, vel, thrust)
    for i in range(200):
        scalar, _ = reward_scalar(tuple(pos[i]) + tuple(vel[i]) + (2000.0,), tuple(thrust[i]))
        assert scalar == pytest.approx(batched[i], abs=1e-12)


def test_precision_bonus_rises_towards_the_pad_and_is_off_by_default():
    # landed at 1.414 m from the pad: + 10 * (1 - 1.414 / 5) = 7.17 on top of kappa; 0 when off
    cfg = replace(REWARD, precision_bonus=10.0)
    pos, vel, thrust = np.array([1.0, 1.0, 0.005]), np.array([0.5, 0.0, -1.0]), np.zeros(3)
    gain = reward(pos, vel, thrust, cfg) - reward(pos, vel, thrust)
    assert gain == pytest.approx(10.0 * (1.0 - math.sqrt(2.0) / 5.0), abs=1e-12)
    centre = reward(np.array([0.0, 0.0, 0.005]), vel, thrust, cfg) - reward(
        np.array([0.0, 0.0, 0.005]), vel, thrust
    )
    assert centre == pytest.approx(10.0, abs=1e-12)
    # not landed (too fast): no bonus of either kind
    fast = np.array([0.5, 0.0, -2.5])
    assert reward(pos, fast, thrust, cfg) == pytest.approx(reward(pos, fast, thrust), abs=1e-12)
    scalar, ok = reward_scalar(tuple(pos) + tuple(vel) + (1700.0,), tuple(thrust), cfg)
    assert ok and scalar == pytest.approx(float(reward(pos, vel, thrust, cfg)), abs=1e-12)
