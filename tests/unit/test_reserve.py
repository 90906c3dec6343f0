"""The braking reserve sized from measurements (pd_core.reserve): the gate and the teacher."""

import numpy as np
import pytest

from pd_core.controllers import make_controller
from pd_core.dispersions import Dispersions
from pd_core.evaluate import rollout
from pd_core.reserve import ReserveAdaptiveTeacher, ReserveGate, measured_nominal
from pd_core.shield import ShieldedActor

SEED = 5_000_000
NOMINAL = {
    "delay_steps": np.array([0]),
    "gain": np.array([1.0]),
    "gain_sd": np.array([0.005]),
    "force_sd_n": np.array([100.0]),
    "nav_noisy": np.array([False]),
}


@pytest.mark.parametrize(
    "change",
    [
        {"delay_steps": np.array([1])},
        {"gain_sd": np.array([0.02])},  # not yet measured to 1 %
        {"gain": np.array([0.975])},  # 3-sigma bound 0.96: maybe 4 % short
        {"force_sd_n": np.array([300.0])},  # 3x the Table 3 gusts
        {"nav_noisy": np.array([True])},
    ],
)
def test_gate_refuses_each_unmeasured_or_off_nominal_condition(change):
    gate = ReserveGate()
    assert measured_nominal(NOMINAL, gate).tolist() == [True]
    assert measured_nominal({**NOMINAL, **change}, gate).tolist() == [False]


def _fly(dispersions: Dispersions) -> tuple[ReserveAdaptiveTeacher, np.ndarray, np.ndarray]:
    adaptive = ReserveAdaptiveTeacher()
    ro = rollout(adaptive, 8, SEED, dispersions=dispersions)
    base = rollout(
        ShieldedActor(make_controller("zemzev-vernier")), 8, SEED, dispersions=dispersions
    )
    return adaptive, ro.fuel_kg, base.fuel_kg


def test_nominal_landers_fly_lean_once_the_engine_is_measured_and_burn_less():
    adaptive, fuel, base = _fly(Dispersions())
    # lean from a few seconds into braking (before it: thrust unmeasured): 57 % of the steps
    assert 0.4 < adaptive.lean_steps / adaptive.steps < 0.75
    # 310 against 325 kg median (the baseline is 1.12x the fuel-optimal landing, this 1.07x)
    assert np.median(base - fuel) > 8.0
    assert np.all(fuel < base)


@pytest.mark.parametrize(
    "dispersions",
    [
        Dispersions("delay", delay_steps=1),
        Dispersions("nav", nav_position_sigma_m=3.0, nav_velocity_sigma_mps=0.3),
    ],
)
def test_delay_or_navigation_noise_keeps_the_full_reserve_to_the_bit(dispersions):
    adaptive, fuel, base = _fly(dispersions)
    assert adaptive.lean_steps == 0
    np.testing.assert_array_equal(fuel, base)


def test_evidence_reports_the_lag_and_the_noise_the_layer_measured():
    adaptive = ReserveAdaptiveTeacher()
    d = Dispersions("delay-nav", delay_steps=1, nav_position_sigma_m=3.0)
    rollout(adaptive, 4, SEED, dispersions=d)
    e = adaptive.latency.evidence(np.arange(4))
    assert e["delay_steps"].tolist() == [1, 1, 1, 1]
    assert e["nav_noisy"].all()
    assert np.all(e["gain_sd"] < 0.05)  # a whole flight of braking measured the engine
