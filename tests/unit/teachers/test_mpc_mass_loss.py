"""Issue 68, item 2: the reserve teacher quantising inside the braking limit that counts on the
mass lost while braking (`MPCParams.brake_mass_loss`), on the vertical thrust fraction its
runtime layer counts on (`MPCParams.layer_thrust_fraction`, handed over by `Runtime`)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from pd_core.config import RL_THRUST
from pd_core.episodes import rollout
from pd_core.runtime.config import LatencyConfig, RulesConfig, RuntimeConfig
from pd_core.runtime.layer import Runtime
from pd_core.teachers.mpc import MPCController, MPCParams, brake_limited
from pd_core.teachers.registry import CONTROLLERS, RESERVE_STATE_PARAMS, make_controller

T_MAX_N = float(RL_THRUST.max_n[2])
ML_NAME = "mpc-fuel-reserve-state-ml"
PLAN_NAME = "mpc-fuel-reserve-state-ml-plan"
LF_NAME = "mpc-fuel-reserve-state-lf"
# 2500 m, 2000 kg: the limit at the mass now is 103.2 m/s, counting on the mass lost while
# braking 109.4 m/s (docs/experiments/2026-12-04-braking-law-and-beyond.md)
BETWEEN = np.array([0.0, 0.0, 2500.0, 0.0, 0.0, -106.0, 2000.0])


def _vertical_level(ctl: MPCController, action: int) -> int:
    return int(ctl.actions.level_table[action][2])


def _coast(ctl: MPCController) -> int:
    """The action with zero lateral and the lowest vertical level."""
    mid = [(n - 1) // 2 for n in ctl.actions.n_per_axis[:2]]
    return int(ctl.actions.levels_to_action(np.array([[mid[0], mid[1], 0]]))[0])


def test_new_fields_are_off_in_every_teacher_but_the_ml_and_lf_ones() -> None:
    assert MPCParams().brake_mass_loss is False and MPCParams().layer_thrust_fraction is False
    assert MPCParams().plan_brake_margin_mps is None
    assert {ML_NAME, PLAN_NAME, LF_NAME} <= set(CONTROLLERS)
    for name in CONTROLLERS:
        ctl = make_controller(name)
        if not isinstance(ctl, MPCController):
            continue
        ml = name in (ML_NAME, PLAN_NAME)
        lf = ml or name in (LF_NAME, LF_NAME + "-hold")
        assert ctl.params.brake_mass_loss is ml and ctl.params.layer_thrust_fraction is lf, name
        assert ctl.takes_thrust_fraction is lf
        assert (ctl._envelope() is not None) is (name == PLAN_NAME), name
    ml = make_controller(ML_NAME)
    assert ml.name == ML_NAME
    # otherwise the recipe's teacher, setting for setting
    assert replace(ml.params, brake_mass_loss=False, layer_thrust_fraction=False) == (
        RESERVE_STATE_PARAMS
    )
    lf = make_controller(LF_NAME)
    assert replace(lf.params, layer_thrust_fraction=False) == RESERVE_STATE_PARAMS


def test_plan_envelope_is_the_layers_limit_on_the_counted_fraction() -> None:
    ctl = make_controller(PLAN_NAME)
    ctl._row_fraction = 0.8
    env = ctl._envelope()
    assert env is not None and env.mass_loss and env.margin_mps == pytest.approx(0.35)
    assert env.gate_m == pytest.approx(ctl.params.gate_altitude_m)
    # the limit it plans inside is the one the layer's rules check on 80 % of the thrust: from
    # 2500 m, 2000 kg, a full-thrust step at 0.5 m/s under it passes, a coasting step at 0.5 m/s
    # over it fires
    vmax = float(env.limits(np.array([2500.0]), np.array([2000.0]))[0][0])
    s = BETWEEN.copy()
    s[5] = -(vmax - 0.5)
    assert not brake_limited(s, 0.8 * T_MAX_N, 0.8 * T_MAX_N, mass_loss=True)
    s[5] = -(vmax + 0.5)
    assert brake_limited(s, 0.0, 0.8 * T_MAX_N, mass_loss=True)


def test_mass_loss_teacher_coasts_where_only_the_constant_mass_limit_fires() -> None:
    assert brake_limited(BETWEEN, 0.0, T_MAX_N)  # the old limit: 106 m/s is too fast
    assert not brake_limited(BETWEEN, 0.0, T_MAX_N, mass_loss=True)  # the new: inside
    old = make_controller("mpc-fuel-reserve-state")
    new = make_controller(ML_NAME)
    coast = _coast(new)
    top = new.actions.n_per_axis[2] - 1
    assert _vertical_level(old, old._within_brake_limit(BETWEEN, coast)) == top
    assert new._within_brake_limit(BETWEEN, coast) == coast


def test_layer_fraction_raises_the_level_where_the_layers_80_percent_limit_would() -> None:
    # 2500 m, 2000 kg at 76.75 m/s: well inside the limit on full thrust (109.4 m/s), just
    # outside it on 80 % of the thrust for a coasting step (not for a step at half thrust)
    s = BETWEEN.copy()
    s[5] = -76.75
    assert not brake_limited(s, 0.0, T_MAX_N, mass_loss=True)
    assert brake_limited(s, 0.0, 0.8 * T_MAX_N, mass_loss=True)
    new = make_controller(ML_NAME)
    coast = _coast(new)
    assert new._within_brake_limit(s, coast, 1.0) == coast
    raised = new._within_brake_limit(s, coast, 0.8)
    lz = _vertical_level(new, raised)
    assert lz > 0
    # the lowest level the layer's rules (mass loss, 80 % counted) let pass, as the layer judges
    t_z = float(new.actions.thrust(raised)[2])
    assert not brake_limited(s, 0.8 * t_z, 0.8 * T_MAX_N, mass_loss=True)
    below = new.actions.level_table[raised].copy()
    below[2] -= 1
    t_below = float(new.actions.levels_to_thrust(below)[2])
    assert brake_limited(s, 0.8 * t_below, 0.8 * T_MAX_N, mass_loss=True)
    # a teacher without the field ignores the fraction
    old = make_controller("mpc-fuel-reserve-state")
    assert old._within_brake_limit(s, coast, 0.8) == coast


class _Spy:
    """An actor recording the fractions a Runtime hands it (coasts straight down)."""

    takes_thrust_fraction = True

    def __init__(self) -> None:
        self.seen: list[np.ndarray] = []

    def take_thrust_fraction(self, fraction: np.ndarray) -> None:
        self.seen.append(np.array(fraction))

    def act_batch(self, states: np.ndarray) -> np.ndarray:
        return np.zeros(len(states), dtype=np.int64)


def test_runtime_hands_the_counted_fraction_only_to_an_actor_that_takes_it() -> None:
    s = np.array([[0.0, 0.0, 2000.0, 0.0, 0.0, -60.0, 1900.0]] * 3)
    weakest = RuntimeConfig(latency=replace(LatencyConfig(), unmeasured_thrust=0.8))
    spy = _Spy()
    rt = Runtime(spy, weakest)
    rt.begin_episodes(3)
    rt.step_rows(s, np.arange(3))
    # unmeasured engine: the rules count on 0.8, and so is the actor told
    np.testing.assert_allclose(spy.seen[-1], [0.8, 0.8, 0.8])
    spy_default = _Spy()
    Runtime(spy_default, RuntimeConfig()).step_rows(s, np.arange(3))
    np.testing.assert_allclose(spy_default.seen[-1], [1.0, 1.0, 1.0])
    # rules that do not count on the measured thrust: full thrust
    no_meas = replace(weakest, rules=replace(RulesConfig(), measured_thrust=False))
    spy_nm = _Spy()
    Runtime(spy_nm, no_meas).step_rows(s, np.arange(3))
    np.testing.assert_allclose(spy_nm.seen[-1], [1.0, 1.0, 1.0])
    spy_no = _Spy()
    spy_no.takes_thrust_fraction = False
    Runtime(spy_no, weakest).step_rows(s, np.arange(3))
    assert spy_no.seen == []


@pytest.mark.timeout(600)
def test_ml_teacher_behind_the_matching_layer_is_never_braked() -> None:
    rules = replace(RulesConfig(), brake_mass_loss=True)
    cfg = RuntimeConfig(rules=rules, latency=replace(LatencyConfig(), unmeasured_thrust=0.8))
    rt = Runtime(make_controller(ML_NAME), cfg)
    ro = rollout(rt, 2, seed=0)
    assert ro.landed.all(), np.flatnonzero(~ro.landed)
    # the teacher keeps the layer's limit itself: the layer never raises one of its actions
    assert rt.counts["brake"] == 0, rt.counts
