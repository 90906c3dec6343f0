"""The reachability oracle: it rebuilds exactly what campaign episodes flew, lands what can be
landed, proves out of reach what cannot, and adds its figures to `pd-eval --reachability`."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from pd_core import dynamics
from pd_core.actions import DEFAULT_ACTIONS
from pd_core.cli import evaluate as pd_eval
from pd_core.config import DT_S, G0_MPS2, ISP_S, TABLE1
from pd_core.dispersions import NOMINAL, SCENARIOS, Dispersions, rotation_matrix
from pd_core.episodes import rollout
from pd_core.experiments.reachability import (
    braking_authority,
    delivered_limits,
    episode_starts,
    plan_gains,
    reachable,
    touchdown_speed_bound,
)
from pd_core.teachers.registry import make_controller

N = 12


@pytest.mark.parametrize("name", ["mass", "all"])
def test_rebuilt_starts_are_the_first_states_rollout_flew(name):
    d = SCENARIOS[name]
    ro = rollout(make_controller("zemzev"), N, seed=11, keep_trajectories=N, dispersions=d)
    states, draws = episode_starts(d, 11, range(N))
    np.testing.assert_array_equal(states, np.array([p[0] for p in ro.trajectories]))
    assert [dr.mass_kg for dr in draws] == list(states[:, 6])  # the scenario's mass draw
    assert np.ptp(states[:, 6]) > 100.0  # ... spread over 1800-2200 kg, not Table 3's 2000 kg
    # any subset, in any order: episode i is on env seed 11 + i whatever else is rebuilt
    some, _ = episode_starts(d, 11, [7, 2])
    np.testing.assert_array_equal(some, states[[7, 2]])
    if name == "all":  # the 25 % wider box: z beyond Table 3's 2400-2600 m for some episode
        assert np.any((states[:, 2] < 2400.0) | (states[:, 2] > 2600.0))


def test_rebuilt_draws_explain_every_step_flown():
    """Without disturbance each recorded step is the plant's step under the rebuilt gains, Isp,
    misalignment and the 1-step delay (to 1e-14 m); a gain off by 1e-3 misses by ~1e-3."""
    d = SCENARIOS["all"]
    ro = rollout(make_controller("zemzev"), 6, 5, False, keep_trajectories=6, dispersions=d)
    _, draws = episode_starts(d, 5, range(6))
    for path, acts, dr in zip(ro.trajectories, ro.actions, draws, strict=True):
        cmd = DEFAULT_ACTIONS.thrust(acts)
        applied = np.concatenate([np.zeros((d.delay_steps, 3)), cmd])[: len(cmd)]
        delivered = (dr.rotation @ (dr.thrust_gain * applied).T).T
        nxt = dynamics.step(path[:-1], delivered, np.zeros_like(delivered), DT_S, isp_s=dr.isp_s)
        np.testing.assert_allclose(nxt, path[1:], rtol=1e-12, atol=1e-9)
    _, nominal = episode_starts(NOMINAL, 5, [0])
    assert np.all(nominal[0].thrust_gain == 1.0) and nominal[0].isp_s == ISP_S


def test_rebuilt_draws_explain_the_beyond_parts_flown():
    """The thrust factor from its onset step, the steady wind and the 2-step delay of a
    `data/beyond.yaml`-like scenario, rebuilt, explain every step to 1e-9 m (no disturbance)."""
    d = Dispersions(
        "mix", thrust_factor=(0.8, 1.0), thrust_factor_onset_s=(2.0, 20.0), delay_steps=2,
        wind_force_n=400.0, nav_position_bias_m=5.0,
    )  # fmt: skip
    ro = rollout(make_controller("zemzev"), 6, 5, False, keep_trajectories=6, dispersions=d)
    _, draws = episode_starts(d, 5, range(6))
    for path, acts, dr in zip(ro.trajectories, ro.actions, draws, strict=True):
        cmd = DEFAULT_ACTIONS.thrust(acts)
        applied = np.concatenate([np.zeros((2, 3)), cmd])[: len(cmd)]
        k = np.arange(len(cmd))[:, None]
        gain = dr.thrust_gain * np.where(k >= dr.thrust_onset_step, dr.thrust_factor, 1.0)
        wind = np.broadcast_to(dr.wind_n, applied.shape)
        nxt = dynamics.step(path[:-1], gain * applied, wind, DT_S, isp_s=dr.isp_s)
        np.testing.assert_allclose(nxt, path[1:], rtol=1e-12, atol=1e-9)
        assert 10 <= dr.thrust_onset_step <= 100 and dr.nav_bias is not None
        weakest, strongest = plan_gains(dr)
        np.testing.assert_array_equal(weakest, dr.thrust_gain * dr.thrust_factor)
        np.testing.assert_array_equal(strongest, dr.thrust_gain)


def test_the_wind_shifts_what_the_plan_may_ask_of_the_thrusters():
    lim = delivered_limits(np.full(3, 0.9), wind_n=np.array([400.0, -300.0, 0.0]))
    np.testing.assert_allclose(lim.lo, [-9000.0 + 400.0, -9000.0 - 300.0, 0.0])
    np.testing.assert_allclose(lim.hi, [9000.0 + 400.0, 9000.0 - 300.0, 11700.0])
    # Table 3's centre at 85 % thrust lands against a 400 N wind; the proof ignores the wind
    s0 = np.array([750.0, 0.0, 2500.0, -40.0, 0.0, -80.0, 2000.0])
    v = reachable(s0, np.full(3, 0.85), wind_n=np.array([0.0, 400.0, 0.0]))
    assert v.status == "reachable"
    # an engine that weakens late: the proof counts on the strongest gains, the plan the weakest
    fast = np.array([0.0, 0.0, 1500.0, 0.0, 0.0, -95.0, 2000.0])
    assert reachable(fast, np.full(3, 0.8)).out_of_reach
    assert not reachable(fast, np.full(3, 0.8), bound_thrust_gain=np.ones(3)).out_of_reach


def test_a_table1_corner_is_reachable_with_the_worst_thrusters():
    # Table 1's fastest corner, heavy enough (2000 kg), thrusters at -5 %, Isp -5 %, 1-step delay
    s0 = np.array([TABLE1.hi[0], TABLE1.hi[1], 2500.0, TABLE1.lo[3], TABLE1.hi[4], -90.0, 2000.0])
    v = reachable(s0, np.full(3, 0.95), 0.95 * ISP_S, delay_steps=1)
    assert v.status == "reachable" and v.touchdown_speed_bound_mps == 0.0
    # fuel between the rocket equation's ideal for |v0| = 117 m/s and Table 7's 690 kg maximum
    ideal = 2000.0 * (1.0 - math.exp(-np.linalg.norm(s0[3:6]) / (ISP_S * G0_MPS2)))
    assert ideal < v.plan_fuel_kg < 690.0


def test_300_m_at_minus_100_mps_is_proven_out_of_reach():
    """With every thruster at full the mass falls by < 17 kg/s, so over the < 4 s to the ground
    the net deceleration stays below 13 kN / 2130 kg - 3.72 = 2.38 m/s^2: touchdown at
    >= sqrt(100^2 - 2 * 2.38 * 300) = 92.6 m/s, and below 100 m/s since it does decelerate."""
    s0 = np.array([0.0, 0.0, 300.0, 0.0, 0.0, -100.0, 2200.0])
    v = reachable(s0, np.ones(3), ISP_S)
    assert v.out_of_reach and 92.6 < v.touchdown_speed_bound_mps < 100.0
    # the fuel optimum of Eq. 4 (no altitude constraint) "lands" only by braking ~2 km of
    # stopping distance through the ground and climbing back
    assert v.fuel_ocp_min_altitude_m < -1000.0
    # the delay's unpowered first step only makes it worse; the bound grows with the mass
    assert touchdown_speed_bound(s0, np.ones(3), ISP_S, 1) > v.touchdown_speed_bound_mps
    heavier = s0 + [0, 0, 0, 0, 0, 0, 100.0]
    assert touchdown_speed_bound(heavier, np.ones(3)) > v.touchdown_speed_bound_mps


def test_braking_authority_counts_gains_and_the_misalignment_exactly():
    assert braking_authority(np.full(3, 0.95)) == pytest.approx((12350.0, 31350.0))
    # 2 deg about x: 13 kN cos 2 deg up, plus the 10 kN j thruster's sin 2 deg = 349 N of lift
    rot = rotation_matrix(np.array([1.0, 0.0, 0.0]), math.radians(2.0))
    up, l1 = braking_authority(np.ones(3), rot)
    c, s = math.cos(math.radians(2.0)), math.sin(math.radians(2.0))
    assert up == pytest.approx(13e3 * c + 10e3 * s, rel=1e-12) and l1 > 33e3
    s0 = np.array([0.0, 0.0, 300.0, 0.0, 0.0, -100.0, 2200.0])
    assert touchdown_speed_bound(s0, np.ones(3), rotation=rot) < touchdown_speed_bound(
        s0, np.ones(3)
    )


def test_campaign_reachability_column_and_json(tmp_path, capsys):
    """A 2-step delay (zemzev loses episodes that can be landed) and a heavy scenario
    (2400-3000 kg: some episodes cannot stop, 13 kN lifts at most 3495 kg on Mars)."""
    f = tmp_path / "s.yaml"
    f.write_text(
        "scenarios:\n  - {name: delay2, delay_steps: 2}\n  - {name: heavy, mass_kg: [2400, 3000]}\n"
    )
    argv = ["--controller", "zemzev", "--name", "zz", "--episodes", "30", "--seed", "40"]
    argv += ["--dispersions", str(f), "--no-progress"]
    assert pd_eval.main(argv + ["--out", str(tmp_path / "plain")]) == 0
    plain_text = capsys.readouterr().out
    assert pd_eval.main(argv + ["--out", str(tmp_path / "r"), "--reachability"]) == 0
    text = capsys.readouterr().out
    assert "success % of reachable" in text and "out of reach" in text
    assert "out of reach" not in plain_text  # without the flag: the table as before
    plain = json.loads((tmp_path / "plain" / "campaign.json").read_text())
    t = json.loads((tmp_path / "r" / "campaign.json").read_text())
    assert "reachability" not in plain
    scenarios = {
        "delay2": Dispersions("delay2", delay_steps=2),
        "heavy": Dispersions("heavy", mass_kg=(2400, 3000)),
    }
    for name, d in scenarios.items():
        cell, r = t["results"][name]["zz"], t["reachability"][name]
        before = {k: v for k, v in cell.items() if not k.endswith("_reachable")}
        assert before == plain["results"][name]["zz"]
        failed = set(
            np.flatnonzero(~rollout(make_controller("zemzev"), 30, 40, dispersions=d).landed)
        )
        out = set(r["out_of_reach_episodes"])
        assert r["checked_episodes"] == len(failed) and len(out) == r["out_of_reach"]
        assert out <= failed and set(r["undecided_episodes"]) <= failed - out
        assert cell["episodes_reachable"] == 30 - len(out)
        landed = 30 - len(failed)
        assert cell["success_rate_reachable"] == pytest.approx(landed / (30 - len(out)))
        for i in out:  # evidence: even full thrust arrives at >= 2 m/s (Eq. 12's limit)
            assert r["evidence"][str(i)]["touchdown_speed_bound_mps"] >= 2.0
    assert t["reachability"]["delay2"]["checked_episodes"] >= 1  # a failure, judged reachable
    assert t["reachability"]["delay2"]["out_of_reach"] == 0
    assert t["results"]["delay2"]["zz"]["success_rate_reachable"] < 1.0
    heavy = t["reachability"]["heavy"]
    assert 0 < heavy["out_of_reach"] < heavy["checked_episodes"]  # some proven, some landable
    assert pd_eval.main(["--controller", "zemzev", "--reachability"]) == 2
