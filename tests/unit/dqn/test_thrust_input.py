"""Issue 68, item 3: a network that also sees the vertical thrust fraction its runtime layer
counts on (`TrainConfig.thrust_input`), from the layer to the first layer and from the
demonstrations and DAgger labels into the memory."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from pd_core.demonstrations.dagger import ShadowTeacher, label_transitions
from pd_core.demonstrations.teacher_flown import FractionRecorder
from pd_core.dqn.actor import TorchGreedy
from pd_core.dqn.config import check_config, preset
from pd_core.dqn.network import QNetwork
from pd_core.episodes import rollout
from pd_core.runtime.config import RuntimeConfig
from pd_core.runtime.layer import Runtime
from pd_core.runtime.policy_file import load_policy, save_policy
from pd_core.state import scale_inputs, scale_state, thrust_input
from pd_core.teachers.registry import make_controller

STATES = np.array(
    [
        [500.0, -300.0, 2400.0, -40.0, 10.0, -80.0, 2000.0],
        [3.0, -1.0, 30.0, 0.5, -0.2, -6.0, 1720.0],
    ]
)
CANDIDATE = "brake_mass_loss=1,unmeasured_thrust=0.8"


def _net(thrust: bool, seed: int = 0) -> QNetwork:
    torch.manual_seed(seed)
    return QNetwork(7, 147, (16, 8), "tanh", near_pad=True, thrust_input=thrust)


def test_thrust_input_is_zero_on_a_nominal_engine_and_one_at_the_weakest_promised() -> None:
    np.testing.assert_allclose(thrust_input(np.array([1.0, 0.9, 0.8])), [0.0, 0.5, 1.0], atol=1e-6)
    rows = np.hstack([STATES, [[1.0], [0.8]]])
    inputs = scale_inputs(rows)
    assert inputs.shape == (2, 8) and inputs.dtype == np.float32
    np.testing.assert_array_equal(inputs[:, :7], scale_state(STATES))
    np.testing.assert_allclose(inputs[:, 7], [0.0, 1.0], atol=1e-6)
    with pytest.raises(ValueError, match="7 state values or 8"):
        scale_inputs(np.zeros((2, 6)))


def test_a_widened_network_values_a_nominal_engine_as_the_network_it_came_from() -> None:
    old, new = _net(False), _net(True, seed=1)
    new.widened_from(old)
    assert new.shape_metadata()["thrust_input"] is True
    assert "thrust_input" not in old.shape_metadata()
    obs = torch.from_numpy(scale_state(STATES))
    nominal = torch.cat([obs, torch.zeros(2, 1)], dim=1)
    # the same values to float32 rounding (the first layer sums one more, zero, product)
    torch.testing.assert_close(new(nominal), old(obs), rtol=0, atol=1e-6)
    with pytest.raises(ValueError, match="cannot widen"):
        old.widened_from(new)


def test_the_policy_file_flies_the_fraction_the_layer_hands_over_as_torch_computes_it(
    tmp_path,
) -> None:
    net = _net(True)
    with torch.no_grad():  # make the thrust column matter
        net.net[0].weight[:, 7] = torch.linspace(-3.0, 3.0, net.net[0].weight.shape[0])
    save_policy(tmp_path / "p", net, RuntimeConfig().with_settings(CANDIDATE), {})
    runtime = load_policy(tmp_path / "p")
    numpy_net = runtime.actor
    assert numpy_net.takes_thrust_fraction
    for fraction in (np.array([1.0, 1.0]), np.array([0.8, 0.9])):
        numpy_net.take_thrust_fraction(fraction)
        q = numpy_net.q_values(STATES)
        obs = scale_inputs(np.hstack([STATES, fraction[:, None]]))
        want = net(torch.from_numpy(obs)).detach().numpy()
        np.testing.assert_allclose(q, want, rtol=1e-5, atol=1e-5)
    # the fraction is used once: the next call (the network alone) sees a nominal engine
    numpy_net.take_thrust_fraction(np.array([0.8, 0.8]))
    numpy_net.q_values(STATES)
    nominal = net(torch.from_numpy(scale_inputs(np.hstack([STATES, np.ones((2, 1))]))))
    np.testing.assert_allclose(numpy_net.q_values(STATES), nominal.detach().numpy(), atol=1e-5)
    torch_actor = TorchGreedy(net)
    torch_actor.take_thrust_fraction(np.array([0.8, 0.9]))
    numpy_net.take_thrust_fraction(np.array([0.8, 0.9]))
    np.testing.assert_array_equal(torch_actor.act_batch(STATES), numpy_net.act_batch(STATES))


def test_the_layer_hands_over_80_percent_until_the_engine_is_measured() -> None:
    rec = FractionRecorder(make_controller("zemzev-vernier"))
    runtime = Runtime(rec, RuntimeConfig().with_settings(CANDIDATE))
    ro = rollout(runtime, 3, 0, keep_trajectories=3)
    per = rec.per_episode([len(a) for a in ro.actions])
    assert [len(p) for p in per] == [len(a) for a in ro.actions]
    for p in per:
        assert p[0] == pytest.approx(0.8)  # nothing measured at the first step
        assert p[-1] == pytest.approx(1.0, abs=0.05)  # a nominal engine, measured in flight
    rec_default = FractionRecorder(make_controller("zemzev-vernier"))
    rollout(Runtime(rec_default, RuntimeConfig()), 1, 0)
    assert rec_default.steps[0][0] == 1.0  # the default layer counts on nominal thrust


def test_shadow_teacher_records_the_fraction_with_each_state_and_labels_carry_it() -> None:
    student = load_policy("models/pd_dqn_ocp.pt", layer="never").actor
    shadow = ShadowTeacher(student, make_controller("mpc-fuel-reserve-state-ml"))
    runtime = Runtime(shadow, RuntimeConfig().with_settings(CANDIDATE))
    rollout(runtime, 2, 0)
    fractions = np.concatenate(shadow.fractions)
    assert len(fractions) == len(np.concatenate(shadow.states))
    assert fractions[0] == pytest.approx(0.8) and fractions.max() <= 1.0
    steps = label_transitions(STATES, np.array([0, 146]), np.array([0.8, 0.95]))
    assert steps["states"].shape == (2, 8) and steps["next_states"].shape == (2, 8)
    np.testing.assert_array_equal(steps["next_states"][:, 7], [0.8, 0.95])
    assert label_transitions(STATES, np.array([0, 146]))["states"].shape == (2, 7)


def test_the_thrust_input_needs_the_layer_and_dagger_rounds() -> None:
    cfg = preset("ocp-adapt", init_policy="models/pd_dqn_ocp.pt")
    check_config(cfg)
    assert cfg.thrust_input and cfg.layer_settings == "unmeasured_thrust=0.8"
    assert cfg.controller == "mpc-fuel-reserve-state-lf"
    for bad in (
        preset("ocp", thrust_input=True),
        preset("ocp-adapt", layer=False),
        preset("ocp-adapt", demos="data/demos_7x7x3.npz"),
        preset("ocp-dagger", layer_settings="no_such_setting=1"),
    ):
        with pytest.raises(ValueError):
            check_config(bad)
