"""Policy files: save/load gives identical actions, mismatched files are refused, weights_only."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

import pd_core
from pd_core.dqn.actor import TorchGreedy
from pd_core.dqn.network import QNetwork
from pd_core.lander import sample_initial_state
from pd_core.runtime.config import RuntimeConfig
from pd_core.runtime.policy_file import PolicyLoadError, load_policy, save_policy

torch.set_num_threads(1)


@pytest.fixture()
def saved(tmp_path):
    torch.manual_seed(3)
    net = QNetwork(7, 147, (32, 16, 32), "tanh")
    path = save_policy(tmp_path / "m", net, RuntimeConfig.off(), {"training": {"seed": 3}})
    return net, path


def _states(n: int = 64) -> np.ndarray:
    rng = np.random.default_rng(0)
    s = np.array([sample_initial_state(rng) for _ in range(n)])
    s[: n // 2, 0:3] *= rng.uniform(0, 0.01, size=(n // 2, 1))  # near the pad too
    return s


def test_save_and_load_give_identical_actions(saved):
    net, path = saved
    pol = pd_core.load_policy(path)
    s = _states()
    want = TorchGreedy(net).act_batch(s)
    np.testing.assert_array_equal(pol.actor.act_batch(s), want)
    assert [pol.bare_action(x) for x in s] == want.tolist()
    pol.begin_episode()
    assert [pol.step(x)[0] for x in s] == want.tolist()  # a file without a layer flies bare
    assert isinstance(pol.bare_action(s[0]), int)
    np.testing.assert_allclose(pol.thrust(146), [10e3, 10e3, 13e3])
    meta = json.loads(path.with_suffix(".json").read_text())
    assert meta["network"]["hidden"] == [32, 16, 32] and meta["training"]["seed"] == 3
    for key in ("n_per_axis", "state_scale", "thrust_max_n", "dt_s", "code_version"):
        assert key in meta


@pytest.mark.parametrize(
    ("key", "value", "says"),
    [
        ("n_per_axis", [9, 9, 3], "n_per_axis"),
        ("state_scale", [1, 1, 1, 1, 1, 1, 1], "state_scale"),
        ("thrust_max_n", [1, 1, 1], "thrust_max_n"),
        ("dt_s", 0.1, "dt_s"),
    ],
)
def test_mismatched_metadata_is_refused(saved, key, value, says):
    _, path = saved
    js = path.with_suffix(".json")
    meta = json.loads(js.read_text())
    meta[key] = value
    js.write_text(json.dumps(meta))
    with pytest.raises(PolicyLoadError, match=says):
        load_policy(path)


def test_mismatched_network_shape_is_refused(saved):
    _, path = saved
    js = path.with_suffix(".json")
    meta = json.loads(js.read_text())
    meta["network"]["hidden"] = [32, 16, 33]
    js.write_text(json.dumps(meta))
    with pytest.raises(PolicyLoadError, match="cannot load weights"):
        load_policy(path)


def test_weights_only_refuses_pickled_code(saved, tmp_path):
    _, path = saved

    class Evil:
        def __reduce__(self):
            return (print, ("pwned",))

    torch.save({"x": Evil()}, path)
    with pytest.raises(PolicyLoadError):
        load_policy(path)


def test_missing_file_is_refused(tmp_path):
    with pytest.raises(PolicyLoadError, match="no such file"):
        load_policy(tmp_path / "nothing.pt")
