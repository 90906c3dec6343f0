"""Demonstration memories as files (pd_core.dqn.demo_file): what is built is what is read back,
training on the file is training on a fresh build, and a file made for another config is refused."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from train_configs import small_config

from pd_core.dqn import demo_file
from pd_core.dqn.config import training_reward
from pd_core.dqn.demo_file import (
    DEMO_FILE,
    FILE_FIELDS,
    PROVENANCE_FIELDS,
    read_demo_file,
    write_demo_file,
)
from pd_core.dqn.demo_memory import build_demo_memory
from pd_core.dqn.train import Trainer

ROOT = Path(__file__).resolve().parents[3]
STUDENT = str(ROOT / "models" / "pd_dqn_best.pt")


def _weights(tr: Trainer) -> list[torch.Tensor]:
    return [v.clone() for v in tr.agent.q.state_dict().values()]


def test_a_run_trained_on_its_demo_file_is_the_run_that_built_it_to_the_bit(tmp_path):
    built = Trainer(small_config(tmp_path, "built", seed=4), quiet=True)
    built.run()
    path = built.run_dir / DEMO_FILE
    assert path.is_file()
    again = Trainer(small_config(tmp_path, "again", seed=4, demo_memory=str(path)), quiet=True)
    assert not (again.run_dir / DEMO_FILE).exists()  # read, not built: nothing written
    n = len(built.demo)
    assert len(again.demo) == n > 100
    for col in demo_file.COLUMNS:
        np.testing.assert_array_equal(getattr(again.demo, col)[:n], getattr(built.demo, col)[:n])
    again.run()
    for x, y in zip(_weights(built), _weights(again), strict=True):
        assert torch.equal(x, y)


def test_a_file_made_for_another_config_is_refused_naming_what_differs(tmp_path):
    cfg = small_config(tmp_path, "a", seed=4)
    memory, info = build_demo_memory(cfg, training_reward(cfg))
    path = write_demo_file(tmp_path / "d.npz", memory, cfg, info)
    read_demo_file(path, replace(cfg, batch_demo=8, max_updates=7))  # same memory: accepted
    with pytest.raises(ValueError, match=r"another config: seed: file 4, config 5") as e:
        read_demo_file(path, replace(cfg, seed=5))
    assert "\n" not in str(e.value)
    with pytest.raises(ValueError, match="not a demonstration memory"):
        read_demo_file(ROOT / "data" / "demos_7x7x3.npz", cfg)


class _Reads:
    """A config that records which fields are read."""

    def __init__(self, cfg):
        object.__setattr__(self, "_cfg", cfg)
        object.__setattr__(self, "read", set())

    def __getattr__(self, name):
        self.read.add(name)
        return getattr(self._cfg, name)


def test_the_provenance_holds_every_field_that_makes_the_memory(tmp_path):
    # every branch of the build: the open-loop file, teacher episodes, recovery, labels
    cfg = small_config(
        tmp_path,
        "p",
        demos=str(ROOT / "data" / "demos_7x7x3.npz"),
        controller_demo_episodes=2,
        recovery_demo_episodes=2,
        label_episodes=2,
        init_policy=STUDENT,
    )
    probe = _Reads(cfg)
    build_demo_memory(probe, training_reward(cfg))
    unrecorded = probe.read - set(PROVENANCE_FIELDS) - set(FILE_FIELDS)
    assert unrecorded <= {"address", "batch_demo", "dagger_rounds"}, unrecorded
