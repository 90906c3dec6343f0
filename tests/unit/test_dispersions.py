"""Dispersions change what the plant does by what the equations say, and stay seeded."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pd_core import dynamics
from pd_core.config import DT_S, G0_MPS2, ISP_S, TABLE3
from pd_core.dispersions import SCENARIOS, Dispersions, failure_weights, load_scenarios
from pd_core.episodes import rollout
from pd_core.teachers.zemzev import ZemZevController
from pd_core.vector_env import make_vector_env

HOVER = 73  # levels (3, 3, 1): zero lateral thrust, 6.5 kN up
N = 64


def _env(d: Dispersions | str, n: int = N, disturbance: bool = False):
    env = make_vector_env(n, disturbance=disturbance, autoreset=False, dispersions=d)
    env.reset(seed=500)
    return env


def test_nominal_scenario_is_bit_identical_to_no_dispersions():
    ctl = ZemZevController()
    a = rollout(ctl, 40, seed=3)
    b = rollout(ctl, 40, seed=3, dispersions="nominal")
    np.testing.assert_array_equal(a.final_states, b.final_states)
    np.testing.assert_array_equal(a.returns, b.returns)


def test_thrust_error_scales_the_delivered_thrust_per_thruster():
    env = _env(Dispersions("t10", thrust_error=0.10))
    gain = env._disp.thrust_gain.copy()
    assert np.all(np.abs(gain - 1.0) <= 0.10) and np.ptp(gain) > 0.1  # spread over +-10 %
    s0 = env.states.copy()
    cmd = env.actions.thrust(np.full(N, 146))  # (10, 10, 13) kN
    for _ in range(50):
        env.step(np.full(N, 146))
    want = s0
    for _ in range(50):  # Eq. 2 with the delivered thrust, Eq. 3 with its flow
        want = dynamics.step(want, cmd * gain, np.zeros((N, 3)), DT_S)
    np.testing.assert_allclose(env.states, want, rtol=1e-12, atol=1e-9)
    # the rocket equation for 10 s of constant delivered thrust (T, mdot): what it changes in vz
    t = 50 * DT_S
    tk = cmd * gain
    mdot = np.abs(tk).sum(axis=1) / (ISP_S * G0_MPS2)
    vz = s0[:, 5] - 3.72 * t + tk[:, 2] / mdot * np.log(s0[:, 6] / (s0[:, 6] - mdot * t))
    np.testing.assert_allclose(env.states[:, 5], vz, rtol=1e-10)
    nominal = _env("nominal")
    for _ in range(50):
        nominal.step(np.full(N, 146))
    assert np.abs(env.states[:, 5] - nominal.states[:, 5]).max() > 5.0  # m/s: it matters


def test_isp_error_changes_only_the_mass_flow():
    env = _env(Dispersions("i5", isp_error=0.05))
    isp = env._disp.isp_s.copy()
    assert np.all(np.abs(isp / ISP_S - 1.0) <= 0.05)
    m0 = env.states[:, 6].copy()
    env.step(np.full(N, HOVER))
    np.testing.assert_allclose(m0 - env.states[:, 6], 6500.0 / (isp * G0_MPS2) * DT_S, rtol=1e-12)


def test_misalignment_rotates_the_thrust_by_at_most_its_angle():
    env = _env(Dispersions("m2", misalignment_deg=2.0))
    rot = env._disp.rotation
    cmd = env.actions.thrust(np.full(N, HOVER))
    got = np.einsum("nij,nj->ni", rot, cmd)
    np.testing.assert_allclose(np.linalg.norm(got, axis=1), 6500.0, rtol=1e-12)
    angle = np.degrees(np.arccos(np.clip(got[:, 2] / 6500.0, -1, 1)))
    assert angle.max() <= 2.0 + 1e-9 and angle.max() > 1.0
    s0 = env.states.copy()
    env.step(np.full(N, HOVER))
    np.testing.assert_allclose(env.states, dynamics.step(s0, got, np.zeros((N, 3)), DT_S))


def test_one_step_delay_flies_the_previous_command():
    env = _env("delay")
    s0 = env.states.copy()
    zero = np.zeros((N, 3))
    env.step(np.full(N, 146))  # engines not yet lit: free fall
    s1 = dynamics.step(s0, zero, zero, DT_S)
    np.testing.assert_array_equal(env.states, s1)
    env.step(np.full(N, 0))  # now the first command (146) arrives
    full = np.tile(env.actions.thrust(146), (N, 1))
    np.testing.assert_array_equal(env.states, dynamics.step(s1, full, zero, DT_S))


def test_nav_noise_is_on_the_observation_only():
    noisy, clean = _env("nav-noise"), _env("nominal")
    np.testing.assert_array_equal(noisy.states, clean.states)  # same seed, same initial states
    err = []
    for _ in range(40):
        _, _, _, _, info = noisy.step(np.full(N, HOVER))
        clean.step(np.full(N, HOVER))
        err.append(info["observed_state"] - info["state"])
    np.testing.assert_array_equal(noisy.states, clean.states)  # the plant is untouched
    sd = np.concatenate(err).std(axis=0)
    np.testing.assert_allclose(sd, [1, 1, 1, 0.1, 0.1, 0.1, 10], rtol=0.1)


def test_mass_gusts_and_wide_box_draws():
    nominal = _env("nominal", 400, disturbance=True)
    mass = _env("mass", 400)
    m = mass.states[:, 6]
    assert m.min() >= 1800 and m.max() <= 2200 and np.ptp(m) > 350
    np.testing.assert_array_equal(mass.states[:, :6], nominal.states[:, :6])  # common numbers
    gusts = _env("gusts", 400, disturbance=True)
    np.testing.assert_allclose(gusts._knots, 3.0 * nominal._knots, rtol=1e-15)
    wide = _env("wide-box", 400).states
    box = SCENARIOS["wide-box"].initial_box(TABLE3)
    assert np.all(wide >= box.lo) and np.all(wide <= box.hi)
    outside = (wide < TABLE3.lo) | (wide > TABLE3.hi)
    assert 0.3 < outside[:, :6].any(axis=1).mean() < 0.95


def test_seeded_campaign_repeats_and_does_not_depend_on_chunking():
    ctl = ZemZevController()
    a = rollout(ctl, 30, seed=9, dispersions="all")
    b = rollout(ctl, 30, seed=9, dispersions="all", chunk=7)
    for f in ("final_states", "landed", "steps", "returns", "initial_states"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f))
    c = rollout(ctl, 30, seed=10, dispersions="all")
    assert not np.array_equal(a.final_states, c.final_states)


def test_state_dict_round_trip_continues_exactly():
    env = make_vector_env(8, dispersions="all")
    env.reset(seed=1)
    rng = np.random.default_rng(0)
    for _ in range(300):  # past some episode ends (autoreset draws again)
        env.step(rng.integers(0, 147, 8))
    saved = env.state_dict()
    actions = rng.integers(0, 147, (200, 8))
    a = [env.step(x)[0] for x in actions]
    other = make_vector_env(8, dispersions="all")
    other.load_state_dict(saved)
    b = [other.step(x)[0] for x in actions]
    np.testing.assert_array_equal(np.array(a), np.array(b))
    with pytest.raises(ValueError, match="dispersions"):
        make_vector_env(8, dispersions="mass").load_state_dict(saved)


def test_yaml_scenarios_and_bad_names(tmp_path):
    f = tmp_path / "mine.yaml"
    f.write_text(
        "scenarios:\n  - nominal\n  - {base: mass, name: heavy, mass_kg: [2100, 2400]}\n"
        "  - {name: late, delay_steps: 2, thrust_error: 0.03}\n"
    )
    s = load_scenarios(str(f))
    assert [d.name for d in s] == ["nominal", "heavy", "late"]
    assert s[1].mass_kg == (2100.0, 2400.0) and s[2].delay_steps == 2
    assert [d.name for d in load_scenarios("standard")] == list(SCENARIOS)[:10]
    broad = load_scenarios("broad")
    assert [d.name for d in broad[:10]] == list(SCENARIOS)[:10] and len(broad) == 18
    with pytest.raises(ValueError, match="unknown dispersion scenario"):
        load_scenarios("nominal,windy")
    f.write_text("thrust_eror: 0.1\n")
    with pytest.raises(ValueError, match="thrust_eror"):
        load_scenarios(str(f))
    assert math.isclose(SCENARIOS["all"].misalignment_deg, 2.0)


def test_failure_weights_floor_and_proportion():
    # 200 episodes each: scenario 2 fails 20 %, the others never; half the draws stay uniform
    p = failure_weights(np.array([0, 0, 40]), np.array([200, 200, 200]), uniform_share=0.5)
    rate = np.array([1, 1, 41]) / 202  # Laplace-smoothed
    np.testing.assert_allclose(p, 0.5 / 3 + 0.5 * rate / rate.sum(), rtol=1e-12)
    assert p.sum() == pytest.approx(1.0) and p[2] > 0.6 and p[0] > 0.5 / 3
    # equal failure rates (or nothing flown yet): uniform
    np.testing.assert_allclose(failure_weights(np.zeros(4), np.zeros(4), 0.2), 0.25)
    with pytest.raises(ValueError, match="uniform_share"):
        failure_weights(np.zeros(2), np.zeros(2), 1.5)


def test_scenario_probs_steer_the_draws_and_survive_a_state_dict():
    env = make_vector_env(2000, autoreset=False, dispersions="nominal,mass,all")
    env.reset(seed=4)
    counts = np.bincount(env.episode_scenarios, minlength=3) / 2000
    np.testing.assert_allclose(counts, 1 / 3, atol=0.04)  # uniform by default (4 sigma)
    env.set_scenario_probs(np.array([0.1, 0.1, 0.8]))
    env.reset(seed=4)
    counts = np.bincount(env.episode_scenarios, minlength=3) / 2000
    np.testing.assert_allclose(counts, [0.1, 0.1, 0.8], atol=0.04)
    mass = env.initial_states[env.episode_scenarios == 1, 6]
    assert mass.min() >= 1800 and mass.max() <= 2200 and mass.std() > 50  # the mass scenario's
    other = make_vector_env(2000, autoreset=False, dispersions="nominal,mass,all")
    other.load_state_dict(env.state_dict())
    np.testing.assert_allclose(other.scenario_probs, [0.1, 0.1, 0.8])
    with pytest.raises(ValueError, match="3 non-negative"):
        env.set_scenario_probs(np.array([0.5, 0.5]))


# --- issue 68: one thrust factor (and its onset), navigation bias, steady wind -----------------


def test_one_thrust_factor_scales_every_thruster_from_ignition():
    env = _env(Dispersions("f", thrust_factor=(0.8, 1.0)))
    f = env._disp.thrust_factor.copy()
    assert f.min() >= 0.8 and f.max() <= 1.0 and np.ptp(f) > 0.15
    s0 = env.states.copy()
    cmd = env.actions.thrust(np.full(N, 146))
    for _ in range(20):
        env.step(np.full(N, 146))
    want = s0
    for _ in range(20):
        want = dynamics.step(want, cmd * f[:, None], np.zeros((N, 3)), DT_S)
    np.testing.assert_allclose(env.states, want, rtol=1e-12, atol=1e-9)


def test_a_late_thrust_factor_acts_from_its_onset_step_only():
    d = Dispersions("late", thrust_factor=(0.8, 0.8), thrust_factor_onset_s=(2.0, 6.0))
    env = _env(d)
    onset = env._disp.thrust_onset_step.copy()
    assert onset.min() >= 10 and onset.max() <= 30 and np.ptp(onset) > 10
    s = env.states.copy()
    cmd = env.actions.thrust(np.full(N, 146))
    for k in range(40):
        env.step(np.full(N, 146))
        gain = np.where(k >= onset, 0.8, 1.0)[:, None]
        s = dynamics.step(s, cmd * gain, np.zeros((N, 3)), DT_S)
    np.testing.assert_allclose(env.states, s, rtol=1e-12, atol=1e-9)


def test_navigation_bias_is_constant_bounded_and_on_the_observation_only():
    d = Dispersions("bias", nav_position_bias_m=5.0, nav_velocity_bias_mps=0.2)
    biased, clean = _env(d, 400), _env("nominal", 400)
    first = biased.observed_states - biased.states
    for _ in range(30):
        _, _, _, _, info = biased.step(np.full(400, HOVER))
        clean.step(np.full(400, HOVER))
    np.testing.assert_array_equal(biased.states, clean.states)
    np.testing.assert_allclose(info["observed_state"] - info["state"], first, atol=1e-9)
    r, v = np.linalg.norm(first[:, 0:3], axis=1), np.linalg.norm(first[:, 3:6], axis=1)
    assert r.max() <= 5.0 and v.max() <= 0.2 and np.all(first[:, 6] == 0.0)
    assert 2.0 < r.mean() < 3.0 and 0.08 < v.mean() < 0.12  # size uniform in [0, max]
    assert np.all(np.abs(first[:, 0:3].mean(axis=0)) < 0.5)  # no preferred direction


def test_steady_wind_is_a_horizontal_force_of_its_size():
    env = _env(Dispersions("wind", wind_force_n=400.0))
    w = env._disp.wind_n.copy()
    np.testing.assert_allclose(np.linalg.norm(w, axis=1), 400.0, rtol=1e-12)
    assert np.all(w[:, 2] == 0.0) and np.ptp(np.arctan2(w[:, 1], w[:, 0])) > 5.0
    s = env.states.copy()
    for _ in range(25):
        env.step(np.full(N, HOVER))
        s = dynamics.step(s, env.actions.thrust(np.full(N, HOVER)), w, DT_S)
    np.testing.assert_allclose(env.states, s, rtol=1e-12, atol=1e-9)


def test_the_new_parts_leave_every_other_draw_as_it_was():
    """A scenario with an issue-68 part draws the same initial state, mass and thruster gains
    as the same scenario without it (their draws come from a second stream)."""
    old = _env(Dispersions("m", mass_kg=(1800.0, 2200.0), thrust_error=0.05))
    new = _env(
        Dispersions("m68", mass_kg=(1800.0, 2200.0), thrust_error=0.05, thrust_factor=(0.9, 1.0),
                    nav_position_bias_m=1.0, wind_force_n=100.0)
    )  # fmt: skip
    np.testing.assert_array_equal(old.states, new.states)
    np.testing.assert_array_equal(old._disp.thrust_gain, new._disp.thrust_gain)
    np.testing.assert_array_equal(old._knots, new._knots)


def test_the_beyond_campaign_file_loads_and_round_trips():
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "data" / "beyond.yaml"
    scen = load_scenarios(str(path))
    assert [d.name for d in scen] == [
        "engine80-100", "engine80-100-late", "nav-bias", "heavy15-25", "delay2", "wind400",
        "combined",
    ]  # fmt: skip
    for d in scen:
        assert Dispersions.from_dict(d.to_dict()) == d and not d.nominal
    assert scen[0].thrust_factor == (0.8, 1.0) and scen[3].mass_kg == (2300.0, 2500.0)
    with pytest.raises(ValueError, match="thrust_factor_onset_s"):
        Dispersions("x", thrust_factor_onset_s=(1.0, 2.0))
