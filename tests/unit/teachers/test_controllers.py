"""ZEM/ZEV reference controller: its braking profile stays within the thrust a lander has, its
vertical loop survives a step of delay, it slows down for a lateral error it cannot null, and
its terminal vernier lands on the pad."""

import numpy as np
import pytest

from pd_core.config import DT_S, GRAVITY_MPS2, RL_THRUST
from pd_core.dispersions import SCENARIOS, Dispersions
from pd_core.episodes import final_quantities, rollout
from pd_core.runtime.config import RuntimeConfig
from pd_core.runtime.layer import Runtime
from pd_core.teachers.registry import make_controller
from pd_core.teachers.zemzev import (
    VERNIER_HOLD_PARAMS,
    VERNIER_PARAMS,
    ZemZevController,
    ZemZevParams,
    braking_accel_mps2,
    coast_time_s,
    min_time_to_rest_s,
    profile_accel_for_time_mps2,
)


def test_braking_profile_is_the_nominal_one_up_to_the_thrust_the_mass_allows():
    p = ZemZevParams()
    t_max = RL_THRUST.hi[2]
    a = braking_accel_mps2(np.array([1800.0, 2000.0, 2200.0]), p, t_max)
    # 2000 kg: 0.9 * (13000 / 2000 - 3.72) = 2.50 m/s^2, the nominal profile is kept
    assert a[:2] == pytest.approx([2.5, 2.5])
    assert a[2] == pytest.approx(0.9 * (13e3 / 2200 + GRAVITY_MPS2[2]), abs=1e-12)  # 1.97
    assert a[2] < 13e3 / 2200 + GRAVITY_MPS2[2]  # never steeper than full thrust


def test_heaviest_landers_of_the_mass_scenario_land():
    """With the fixed 2.5 m/s^2 profile every ZEM/ZEV loss of `mass` (seed 0) was above 2170 kg."""
    heavy = Dispersions("heavy", mass_kg=(2180.0, 2200.0))
    ro = rollout(ZemZevController(), 60, seed=0, dispersions=heavy)
    assert ro.landed.all()
    fixed = ZemZevController(ZemZevParams(brake_margin=np.inf))  # the old profile, for contrast
    assert rollout(fixed, 60, seed=0, dispersions=heavy).landed.mean() < 0.95


def test_vertical_loop_stays_damped_with_one_step_of_delay():
    """e[k+1] = e[k] - K dt e[k-1]: poles inside the unit circle for K dt < 1 (0.6 here)."""
    k_dt = ZemZevParams().vz_gain_per_s * DT_S
    assert np.abs(np.roots([1.0, -1.0, k_dt])).max() == pytest.approx(np.sqrt(0.6))
    assert np.abs(np.roots([1.0, -1.0, 6.0 * DT_S])).max() > 1.0  # the former 6/s rings
    delay = SCENARIOS["delay"]
    ro = rollout(ZemZevController(), 200, seed=0, dispersions=delay)
    assert ro.landed.all()
    assert ro.final_states[:, 5].min() > -1.9  # the former gain: -2.12 m/s
    old = ZemZevController(ZemZevParams(vz_gain_per_s=6.0, land_speed_mps=0.8))
    assert rollout(old, 200, seed=0, dispersions=delay).landed.mean() < 0.97


def test_coast_time_is_the_fall_then_brake_time_left_out_of_the_profile():
    """From rest at z with v_land = 0, falling at g then braking at a takes
    sqrt(2 z (g + a) / (g a)); the profile alone counts sqrt(2 z / a)."""
    g, a, z = -GRAVITY_MPS2[2], 2.5, 1500.0
    extra = coast_time_s(np.array([z]), np.array([0.0]), np.array([a]), 0.0)
    assert extra[0] + np.sqrt(2 * z / a) == pytest.approx(np.sqrt(2 * z * (g + a) / (g * a)))
    # on the profile (and faster than it) nothing is left out
    on = -np.sqrt(2.0**2 + 2 * a * z)
    assert coast_time_s(np.array([z, z]), np.array([on, on - 5.0]), a, 2.0) == pytest.approx(0.0)


def test_min_time_to_rest_is_the_bang_bang_time():
    r = np.array([100.0, -100.0, 0.0, 0.0, 10.0])
    v = np.array([0.0, 0.0, 0.0, 10.0, -10.0])
    t = min_time_to_rest_s(r, v, 2.0)
    # from rest: accelerate half the way, brake half: 2 sqrt(r / a)
    assert t[:2] == pytest.approx([2.0 * np.sqrt(50.0)] * 2, rel=1e-12)
    assert t[2] == 0.0
    # at the pad at 10 m/s: 5 s to stop 25 m out, then 2 sqrt(25 / 2) back
    assert t[3] == pytest.approx(5.0 + 2.0 * np.sqrt(12.5), rel=1e-12)
    # 10 m out closing at 10 m/s overshoots to -15 m (5 s), then 2 sqrt(15 / 2) back
    assert t[4] == pytest.approx(5.0 + 2.0 * np.sqrt(7.5), rel=1e-12)


def test_profile_accel_for_time_inverts_the_profile_duration():
    a = profile_accel_for_time_mps2(np.array([2000.0]), np.array([45.0]), 0.5)
    descent = (np.sqrt(0.5**2 + 2.0 * a * 2000.0) - 0.5) / a
    assert descent == pytest.approx([45.0], rel=1e-12)


def test_landers_far_off_sideways_slow_their_descent_and_land():
    """Wide-box corners (|y| ~ 1600 m, drifting away at 40 m/s): full lateral thrust needs more
    time than the nominal profile leaves; only the lateral-limited profile lands them."""
    rng = np.random.default_rng(0)
    n = 40
    s = np.zeros((n, 7))
    side = np.where(rng.uniform(size=n) < 0.5, -1.0, 1.0)
    s[:, 0], s[:, 1] = rng.uniform(400.0, 1200.0, n), side * rng.uniform(1550.0, 1650.0, n)
    s[:, 2:7] = [2450.0, 0.0, 0.0, -85.0, 2000.0]
    s[:, 3], s[:, 4] = rng.uniform(-60.0, 0.0, n), side * 40.0
    assert rollout(ZemZevController(), n, 0, initial_states=s).landed.all()
    unlimited = ZemZevController(ZemZevParams(lateral_limit=False))
    assert rollout(unlimited, n, 0, initial_states=s).landed.mean() < 0.2


def test_vernier_tracks_a_capped_speed_towards_the_pad_only_below_its_altitude():
    """Below 5 m (above the 0.5 m flare): a = 2/s (clip(-r / 1 s, +-0.4 m/s) - v) sideways."""
    c = ZemZevController(VERNIER_PARAMS)
    s = np.array(
        [
            [3.0, -0.1, 3.0, 0.0, 0.2, -0.5, 1700.0],  # far off in i: capped at 0.4 m/s
            [3.0, -0.1, 6.0, 0.0, 0.2, -0.5, 1700.0],  # above the vernier: ZEM/ZEV's command
        ]
    )
    t = c.thrust_command(s)
    assert t[0, 0:2] == pytest.approx(1700.0 * 2.0 * np.array([-0.4, 0.1 - 0.2]), rel=1e-12)
    assert t[1, 0:2] == pytest.approx(ZemZevController().thrust_command(s)[1, 0:2], rel=1e-12)
    assert c.name == "zemzev-vernier" and ZemZevController().name == "zemzev"
    assert make_controller("zemzev-vernier").params == VERNIER_PARAMS
    # K dt = 0.4: the sideways loop stays damped with two steps of delay (z^3 - z^2 + K dt)
    k_dt = VERNIER_PARAMS.vernier_gain_per_s * DT_S
    assert np.abs(np.roots([1.0, -1.0, 0.0, k_dt])).max() < 0.95


def test_hold_keeps_steering_to_the_pad_where_the_vernier_flares():
    """Below the 0.5 m flare, and below the believed ground, the vernier only nulls the sideways
    speed (a = -0.5/s v); the hold variant keeps the vernier's command towards the pad."""
    s = np.array([[2.0, 0.0, -2.0, 0.1, 0.0, -0.5, 1700.0]])  # believed 2 m under the ground
    flare = ZemZevController(VERNIER_PARAMS).thrust_command(s)[0, 0:2]
    hold = ZemZevController(VERNIER_HOLD_PARAMS).thrust_command(s)[0, 0:2]
    assert flare == pytest.approx(1700.0 * -0.5 * np.array([0.1, 0.0]), rel=1e-12)
    assert hold == pytest.approx(1700.0 * 2.0 * np.array([-0.4 - 0.1, 0.0]), rel=1e-12)
    assert make_controller("zemzev-vernier-hold").name == "zemzev-vernier-hold"
    assert (
        make_controller("mpc-fuel-reserve-state-lf-hold").name == "mpc-fuel-reserve-state-lf-hold"
    )


def test_hold_stays_on_the_pad_under_a_navigation_bias():
    """`nav-bias-5` (seed 7,000,000, 300 episodes, behind the layer): a lander that believes it is
    on the ground metres too early drifts off the pad during the descent that remains (vernier: 8
    off the pad); the hold keeps it there (2), and nominal landings stay as they were."""
    off, nominal = {}, {}
    for name, params in (("vernier", VERNIER_PARAMS), ("hold", VERNIER_HOLD_PARAMS)):
        actor = Runtime(ZemZevController(params), RuntimeConfig())
        ro = rollout(actor, 300, 7_000_000, dispersions=SCENARIOS["nav-bias-5"])
        far = final_quantities(ro)["norm_ij_position_m"] >= 5.0
        off[name] = int((~ro.landed & far).sum())
        nominal[name] = rollout(actor, 300, 0)
    assert off["vernier"] >= 5 and off["hold"] <= off["vernier"] // 2
    assert nominal["hold"].landed.all()
    assert nominal["hold"].fuel_kg.mean() == pytest.approx(
        nominal["vernier"].fuel_kg.mean(), rel=0.005
    )


def test_vernier_lands_nearer_the_pad_than_zemzev():
    """ZEM/ZEV's t_go floor (3 s) outlasts the last metres: it overshoots the pad (1.28 m median
    behind the layer, seed 0); the vernier lands within 0.42 m, as often and as softly."""
    out = {}
    for name, params in (("zemzev", ZemZevParams()), ("vernier", VERNIER_PARAMS)):
        ro = rollout(Runtime(ZemZevController(params), RuntimeConfig()), 300, seed=0)
        q = final_quantities(ro)
        assert ro.landed.all()
        assert q["k_velocity_mps"].min() > -1.0
        out[name] = np.median(q["norm_ij_position_m"])
    assert out["zemzev"] > 1.1
    assert out["vernier"] < 0.6
