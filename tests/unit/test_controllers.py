"""ZEM/ZEV reference controller: its braking profile stays within the thrust a lander has."""

import numpy as np
import pytest

from pd_core.config import DT_S, GRAVITY_MPS2, RL_THRUST
from pd_core.controllers import ZemZevController, ZemZevParams, braking_accel_mps2
from pd_core.dispersions import SCENARIOS, Dispersions
from pd_core.evaluate import rollout


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
    old = ZemZevController(ZemZevParams(vz_gain_per_s=6.0))
    assert rollout(old, 200, seed=0, dispersions=delay).landed.mean() < 0.97
