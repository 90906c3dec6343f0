"""Latency compensation: the predicted state is where the delayed plant takes the lander, the lag
is identified under noise and thrust error, a flight without delay is unchanged to the bit, a
policy lands through delays it otherwise loses, a simulator reset clears the memory, and policy
files carry the setting."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from pd_core.actions import DEFAULT_ACTIONS
from pd_core.dispersions import Dispersions, load_scenarios
from pd_core.episodes import rollout
from pd_core.runtime.config import LatencyConfig, NavFilterConfig, RuntimeConfig
from pd_core.runtime.latency import (
    LatencyCompensator,
    lag_residuals,
    window_gain_bound,
)
from pd_core.runtime.layer import Runtime
from pd_core.runtime.policy_file import PolicyLoadError, load_policy
from pd_core.teachers.registry import make_controller
from pd_core.vector_env import make_vector_env

NAV_OFF = NavFilterConfig(enabled=False)
SHORTFALL_SD = LatencyConfig().shortfall_sd


def compensator(max_delay: int, thrust_model: bool = True, nav_filter: bool = False):
    cfg = LatencyConfig(max_delay_steps=max_delay, thrust_model=thrust_model)
    return LatencyCompensator(cfg, NavFilterConfig(enabled=nav_filter))


def with_config(runtime: Runtime, config: RuntimeConfig) -> Runtime:
    return Runtime(runtime.actor, config, runtime.actions, runtime.name, runtime.metadata)


ROBUST = str(Path(__file__).resolve().parents[3] / "models" / "pd_dqn_robust.pt")


@pytest.mark.parametrize(("thrust_model", "atol"), [(False, 1e-9), (True, 1e-2)])
def test_the_prediction_is_where_the_delayed_plant_takes_the_lander(thrust_model, atol):
    """No disturbance: once the lag is known, the state predicted now is the true state two
    steps later: to rounding on the nominal plant, within 1 cm, cm/s and 10 g with the thrust
    matrix identified (the mass burnt within a step biases its force measurement by ~3e-4)."""
    env = make_vector_env(
        1, disturbance=False, autoreset=False, dispersions=Dispersions("d2", delay_steps=2)
    )
    _, info = env.reset(seed=4)
    comp = compensator(4, thrust_model=thrust_model)
    rng = np.random.default_rng(0)
    predicted, true = [], [info["state"][0].copy()]
    for _ in range(40):
        predicted.append(comp.predict(info["observed_state"], np.array([0]))[0])
        a = rng.integers(0, DEFAULT_ACTIONS.n, 1)
        comp.record(np.array([0]), DEFAULT_ACTIONS.table_n[a])
        _, _, _, _, info = env.step(a)
        true.append(info["state"][0].copy())
    assert comp.delay_steps[0] == 2
    for t in range(5, 38):
        np.testing.assert_allclose(predicted[t], true[t + 2], rtol=0, atol=atol)


def _identify(d: Dispersions, seed: int, comp: LatencyCompensator, steps: int, choose):
    """The env after 8 landers of dispersions `d` (env seed `seed`) flew `steps` steps of the
    actions `choose()` (8,) returns, with `comp` fed their observations and commands."""
    env = make_vector_env(8, autoreset=False, dispersions=d)
    _, info = env.reset(seed=seed)
    rows = np.arange(8)
    for _ in range(steps):
        comp.predict(info["observed_state"], rows)
        a = choose()
        comp.record(rows, DEFAULT_ACTIONS.table_n[a])
        _, _, _, _, info = env.step(a)
    return env


def test_the_thrust_matrix_is_identified():
    """A 10 % thrust error on every thruster and a 4 deg misalignment, one step of delay, the
    disturbance on: the lag's thrust matrix ends within 0.01 of the plant's in every entry."""
    d = Dispersions("tm", delay_steps=1, thrust_error=0.1, misalignment_deg=4.0)
    comp = compensator(4)
    rng = np.random.default_rng(1)
    env = _identify(d, 9_500_000, comp, 60, lambda: rng.integers(0, DEFAULT_ACTIONS.n, 8))
    plant = env._disp.rotation * env._disp.thrust_gain[:, None, :]  # rotation @ diag(gain)
    np.testing.assert_array_equal(comp.delay_steps, 1)
    np.testing.assert_allclose(comp.gain[:, 1], plant, rtol=0, atol=0.01)


def test_the_vertical_thrust_scale_is_the_identified_vertical_gain():
    """A 12 % shortfall on every thruster: after a minute of random commands, each lander's
    measured vertical fraction is within 0.01 of what its plant delivers upwards (gain times the
    misalignment's cosine); 1 for a compensator that identifies nothing."""
    d = Dispersions("short", thrust_error=0.12, misalignment_deg=2.0)
    comp = compensator(2)
    rng = np.random.default_rng(2)
    env = _identify(d, 9_600_000, comp, 60, lambda: rng.integers(0, DEFAULT_ACTIONS.n, 8))
    rows = np.arange(8)
    plant = env._disp.rotation[:, 2, 2] * env._disp.thrust_gain[:, 2]
    assert plant.min() < 0.93  # the draw does hold real shortfalls
    np.testing.assert_allclose(comp.gain[rows, comp.delay_steps, 2, 2], plant, rtol=0, atol=0.01)
    bound = comp.vertical_thrust_scale(rows)
    assert np.all(bound >= plant) and np.all(bound <= plant + 0.05)
    np.testing.assert_array_equal(compensator(0).vertical_thrust_scale(rows), 1.0)


def test_under_navigation_noise_the_window_measure_bounds_the_shortfall_sooner():
    """12 % thrust errors and 3 m / 0.3 m/s of navigation noise, 6 s of full vertical thrust:
    the bound the layer uses lies at most 0.1 above each lander's delivered vertical fraction
    and not below it; the per-step filter's bound alone is looser than that on some landers (the
    noise enters every step's velocity change, and a window's change only once)."""
    d = Dispersions("short-noisy", thrust_error=0.12, nav_position_sigma_m=3.0,
                    nav_velocity_sigma_mps=0.3)  # fmt: skip
    comp = compensator(8)
    brake = np.full(8, DEFAULT_ACTIONS.levels_to_action(np.array([3, 3, 2])))
    env = _identify(d, 9_600_000, comp, 31, lambda: brake)
    rows = np.arange(8)
    plant = env._disp.thrust_gain[:, 2]
    bound = comp.vertical_thrust_scale(rows)
    assert np.all(bound >= plant) and np.all(bound <= plant + 0.1), bound - plant
    lag = comp.delay_steps
    per_step = comp.gain[rows, lag, 2, 2] + SHORTFALL_SD * np.sqrt(comp._cov[rows, lag, 2, 2])
    assert np.any(per_step > plant + 0.1), per_step - plant
    assert np.all(
        window_gain_bound(np.zeros(1), np.zeros(1), np.zeros(1), np.zeros(1), 3.0, LatencyConfig())
        > 9
    )


def test_lag_residuals_are_zero_for_the_lag_that_happened():
    issued = np.array([[[0.0, 0.0, 13e3], [3e3, 0.0, 6.5e3], [0.0, 0.0, 0.0]]])
    m = np.array([2000.0])
    dv = (issued[0, 1] / m[0] + np.array([0.0, 0.0, -3.72])) * 0.2
    res = lag_residuals(dv[None], m, issued)
    assert res[0, 1] == pytest.approx(0.0, abs=1e-12)
    assert res[0, 0] == pytest.approx(0.3**2 + 0.65**2, rel=1e-9)  # 3 kN and 6.5 kN at 2 t


@pytest.mark.parametrize("delay", [1, 3])
def test_the_lag_is_identified_under_navigation_noise_and_thrust_error(delay):
    """Metre-class position noise, 0.1 m/s velocity noise and a 5 % thrust error on every
    thruster: every one of 40 landers ends its flight predicting with the lag it had."""
    d = Dispersions(
        "noisy",
        delay_steps=delay,
        thrust_error=0.05,
        nav_position_sigma_m=1.0,
        nav_velocity_sigma_mps=0.1,
        nav_mass_sigma_kg=10.0,
    )
    actor = Runtime(make_controller("zemzev"), RuntimeConfig())
    ro = rollout(actor, 40, 9_100_000, dispersions=d)
    assert ro.landed.all()
    np.testing.assert_array_equal(actor.latency.delay_steps[:40], delay)


@pytest.mark.parametrize("scenario", ["nominal", "gusts"])
def test_without_delay_the_compensated_flight_is_unchanged(scenario):
    """The lag stays 0 where there is none, and the navigation filter stays out where the
    navigation is exact: the same final states to the bit as deciding on the observed state (so
    the nominal figures and the lockstep node tests do not move)."""
    policy = load_policy(ROBUST)
    sc = load_scenarios(scenario)[0]
    on = rollout(policy, 60, 9_200_000, dispersions=sc)
    cfg = policy.config
    no_memory = replace(cfg, latency=LatencyConfig(max_delay_steps=0), nav_filter=NAV_OFF)
    off = rollout(with_config(policy, no_memory), 60, 9_200_000, dispersions=sc)
    np.testing.assert_array_equal(on.final_states, off.final_states)


def test_the_shipped_policy_lands_through_delays_it_loses_without_compensation():
    """Two and four steps (0.4 and 0.8 s) of actuation delay; seed unseen by any run reported."""
    policy = load_policy(ROBUST)
    rates = {}
    for delay in (2, 4):
        d = Dispersions(f"delay-{delay}", delay_steps=delay)
        for on in (True, False):
            cfg = policy.config
            if not on:
                cfg = replace(cfg, latency=LatencyConfig(max_delay_steps=0), nav_filter=NAV_OFF)
            flown = with_config(policy, cfg)
            rates[delay, on] = rollout(flown, 150, 9_300_000, dispersions=d).landed.mean()
    assert rates[2, True] >= 0.99 and rates[4, True] >= 0.99
    assert rates[2, False] <= 0.9 and rates[4, False] <= 0.3


@pytest.mark.parametrize("nav_filter", [False, True])
def test_a_simulator_reset_clears_the_memory(nav_filter):
    comp = compensator(4, nav_filter=nav_filter)
    s = np.array([[0.0, 0.0, 1000.0, 0.0, 0.0, -50.0, 2000.0]])
    comp.predict(s, np.array([0]))
    comp.record(np.array([0]), np.array([[0.0, 0.0, 13e3]]))
    comp.delay_steps[0] = 3
    if nav_filter:
        comp.nav.engaged[0], comp.nav._steps[0] = True, 50
    s2 = s.copy()
    s2[0, 2] = 2500.0  # a new episode: 1.5 km above where the lander was heading
    np.testing.assert_array_equal(comp.predict(s2, np.array([0])), s2)
    assert comp.delay_steps[0] == 0 and not comp._issued.any()
    if nav_filter:  # the filter starts again from this observation
        assert not comp.nav.engaged[0] and comp.nav._steps[0] == 0
        np.testing.assert_array_equal(comp.nav._x[0, :, 0], s2[0, 0:3])


def test_policy_files_pin_the_setting_and_refuse_a_bad_one(tmp_path):
    """The shipped file pins 8 steps; 0 with the filter off is no memory at all, 0 with the filter
    on keeps the filter; a fraction or a step count beyond 10 is refused in one line."""
    meta = json.loads(Path(ROBUST).with_suffix(".json").read_text())
    assert meta["runtime"]["latency"]["max_delay_steps"] == 8
    assert load_policy(ROBUST).latency.max_delay_steps == 8
    off = RuntimeConfig(latency=LatencyConfig(max_delay_steps=0), nav_filter=NAV_OFF)
    assert Runtime(make_controller("zemzev"), off).latency is None
    filter_only = RuntimeConfig(latency=LatencyConfig(max_delay_steps=0))
    assert Runtime(make_controller("zemzev"), filter_only).latency.max_delay_steps == 0
    for bad in (2.5, -1, 11):
        with pytest.raises(ValueError, match="max_delay_steps must be an integer in"):
            LatencyConfig(max_delay_steps=bad)
    pt = tmp_path / "p.pt"
    pt.write_bytes(Path(ROBUST).read_bytes())
    meta["runtime"]["latency"]["max_delay_steps"] = 1.5
    pt.with_suffix(".json").write_text(json.dumps(meta))
    with pytest.raises(PolicyLoadError, match="max_delay_steps") as err:
        load_policy(pt)
    assert "\n" not in str(err.value)


def test_begin_episode_restarts_the_memory():
    """The policy node calls `begin_episode` when the simulator's episode number changes: the
    commands and the lag of the last episode are forgotten (no 50 m jump needed); steps of the
    same episode keep them."""
    policy = load_policy(ROBUST)
    s = np.array([0.0, 0.0, 1000.0, 0.0, 0.0, -50.0, 2000.0])
    policy.begin_episode()
    policy.step(s)
    policy.latency.delay_steps[0] = 3
    policy.latency._issued[0] = 5e3  # commands remembered from episode 1
    policy.step(s)
    assert policy.latency.delay_steps[0] == 3 and policy.latency._issued[0, 1:].min() == 5e3
    policy.begin_episode()
    policy.step(s)
    assert policy.latency.delay_steps[0] == 0
    assert not policy.latency._issued[0, 1:].any()  # only this episode's first command is left
