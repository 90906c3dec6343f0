"""Refused policy files: one line naming the file and the problem, never advice to turn the
weights_only safety off, and a hostile pickle never runs (issue 9 item 13)."""

from __future__ import annotations

import json
import os

import pytest
import torch

from pd_core.dqn.network import QNetwork
from pd_core.runtime.config import RuntimeConfig
from pd_core.runtime.policy_file import PolicyLoadError, load_policy, save_policy


@pytest.fixture()
def saved(tmp_path):
    torch.manual_seed(3)
    return save_policy(tmp_path / "m", QNetwork(7, 147, (32, 16, 32), "tanh"), RuntimeConfig())


def refusal(path) -> str:
    with pytest.raises(PolicyLoadError) as err:
        load_policy(path)
    text = str(err.value)
    assert "\n" not in text and str(path.with_suffix("")) in text, text
    assert "weights_only=False" not in text and "likely succeed" not in text, text
    return text


def test_empty_weights_file(saved):
    saved.write_bytes(b"")
    assert "empty file" in refusal(saved)


def test_empty_metadata_file(saved):
    saved.with_suffix(".json").write_text("")
    assert "empty file" in refusal(saved) and ".json" in refusal(saved)


def test_random_bytes(saved):
    saved.write_bytes(os.urandom(4096))
    assert "not a PyTorch tensor file" in refusal(saved)


def test_wrong_hidden_size_names_the_tensor(saved):
    js = saved.with_suffix(".json")
    meta = json.loads(js.read_text())
    meta["network"]["hidden"] = [32, 16, 33]
    js.write_text(json.dumps(meta))
    text = refusal(saved)
    assert "cannot load weights" in text and "shape" in text and "[33" in text


def test_hostile_pickle_refused_without_running(saved, tmp_path):
    marker = tmp_path / "ran"

    class Evil:
        def __reduce__(self):
            return (marker.write_text, ("pwned",))

    torch.save({"x": Evil()}, saved)
    assert "refused" in refusal(saved)
    assert not marker.exists()


def test_a_plain_pickle_is_refused_in_one_line_without_a_torch_warning(saved, tmp_path):
    """Issue 71 item 7: torch's weights-only unpickler warned about the pickle protocol first."""
    import pickle
    import warnings

    marker = tmp_path / "ran"

    class Evil:
        def __reduce__(self):
            return (marker.write_text, ("pwned",))

    saved.write_bytes(pickle.dumps(Evil(), protocol=4))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        text = refusal(saved)
    assert [str(w.message) for w in caught] == []
    assert "cannot load weights" in text and "\n" not in text
    assert not marker.exists()
