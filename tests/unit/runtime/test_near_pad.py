"""Near-pad inputs: they resolve the last metres, widening a paper network changes no value,
and a file with them flies the same through numpy (Policy) as through torch."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from pd_core.dqn.actor import TorchGreedy
from pd_core.dqn.agent import DQNAgent
from pd_core.dqn.config import TrainConfig
from pd_core.dqn.network import QNetwork
from pd_core.runtime.config import RuntimeConfig
from pd_core.runtime.policy_file import load_policy, save_policy
from pd_core.state import near_pad_features, scale_state

torch.set_num_threads(1)


def _states(n: int = 256) -> np.ndarray:
    """States from the Table 3 box down to the last metre above the pad."""
    rng = np.random.default_rng(5)
    far = np.column_stack(
        [rng.uniform(-1100, 1100, (n, 3)), rng.uniform(-75, 35, (n, 3)), rng.uniform(1500, 2000, n)]
    )
    near = far.copy()
    near[:, 0:3] *= rng.uniform(0.0, 0.002, (n, 1))
    near[:, 3:6] *= rng.uniform(0.0, 0.02, (n, 1))
    return np.concatenate([far, near])


def test_half_a_metre_moves_the_near_pad_input_fifty_times_more_than_eq21():
    s = np.array([[0.0, 0.0, 3.0, 0.0, 0.0, -0.5, 1700.0], [0.5, 0.0, 3.0, 0.3, 0.0, -0.5, 1700.0]])
    eq21 = scale_state(s)
    fine = near_pad_features(eq21)
    assert abs(eq21[1, 0] - eq21[0, 0]) == pytest.approx(0.005, rel=1e-5)
    assert fine[1, 0] - fine[0, 0] == pytest.approx(np.tanh(0.25), rel=1e-5)  # 0.5 m / 2 m
    assert fine[1, 3] - fine[0, 3] == pytest.approx(np.tanh(0.6), rel=1e-5)  # 0.3 m/s / 0.5
    far = near_pad_features(scale_state(np.array([800.0, -900.0, 2500.0, -60, 30, -80, 2000])))
    np.testing.assert_allclose(np.abs(far), 1.0, atol=1e-6)  # saturated away from the pad


def test_widening_a_paper_network_keeps_every_value_and_action():
    torch.manual_seed(0)
    paper = QNetwork(7, 147, (32, 16), "tanh")
    wide = QNetwork(7, 147, (32, 16), "tanh", near_pad=True)
    wide.widened_from(paper)
    assert wide.net[0].weight.shape == (32, 13)
    obs = torch.from_numpy(scale_state(_states()))
    with torch.no_grad():
        np.testing.assert_allclose(wide(obs).numpy(), paper(obs).numpy(), atol=1e-6)
    with pytest.raises(ValueError, match="cannot widen"):
        paper.widened_from(wide)
    with pytest.raises(ValueError, match="cannot widen"):
        QNetwork(7, 147, (32, 32), "tanh", near_pad=True).widened_from(paper)


def test_a_near_pad_file_flies_through_numpy_as_through_torch(tmp_path):
    torch.manual_seed(1)
    net = QNetwork(7, 147, (32, 16, 32), "tanh", near_pad=True)
    for p in net.parameters():  # large enough weights that the near-pad columns decide
        p.data.mul_(3.0)
    path = save_policy(tmp_path / "m", net, RuntimeConfig.off())
    meta = json.loads(path.with_suffix(".json").read_text())
    assert meta["network"]["near_pad"] is True and meta["network"]["n_inputs"] == 7
    pol = load_policy(path)
    s = _states()
    with torch.no_grad():
        want = net(torch.from_numpy(scale_state(s))).numpy()
    np.testing.assert_allclose(pol.actor.q_values(s), want, atol=1e-4)
    np.testing.assert_array_equal(pol.actor.act_batch(s[:256]), TorchGreedy(net).act_batch(s[:256]))
    paper = QNetwork(7, 147, (32, 16, 32), "tanh")
    assert "near_pad" not in paper.shape_metadata()  # files without them keep their metadata


def test_input_normalisation_standardises_the_near_pad_inputs_too():
    agent = DQNAgent(TrainConfig(hidden=(16,), near_pad=True))
    obs = scale_state(_states())
    with torch.no_grad():
        before = agent.q(torch.from_numpy(obs)).numpy()
        x = agent.q.inputs(torch.from_numpy(obs))
        mu, sd = x.mean(0), x.std(0).clamp_min(1e-3)
        w = agent.q.net[0].weight.clone()
    agent.init_input_normalisation(obs)
    with torch.no_grad():
        after = agent.q(torch.from_numpy(obs)).numpy()
        # the folded layer applied to x equals the original layer applied to (x - mu) / sd
        ref = torch.nn.functional.linear((x - mu) / sd, w, agent.q.net[0].bias + (w / sd) @ mu)
        np.testing.assert_allclose(agent.q.net[0](x).numpy(), ref.numpy(), atol=1e-4)
    assert before.shape == after.shape == (len(obs), 147)
