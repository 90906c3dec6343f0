"""A training config small enough for unit tests (a few seconds), shared by the training tests."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

from pd_core.dqn.config import TrainConfig, preset


def small_config(tmp_path: Path, name: str, base: str = "best", **kw: Any) -> TrainConfig:
    """Preset `base` shrunk to a 32x32 network, 4 envs and 120 updates, run folder tmp_path/name;
    `kw` overrides any field."""
    cfg: dict[str, Any] = dict(
        hidden=(32, 32),
        num_envs=4,
        learning_starts=200,
        batch_agent=16,
        batch_demo=16,
        demos="",
        controller_demo_episodes=4,
        pretrain_updates=20,
        max_updates=120,
        eval_every_s=0.0,
        checkpoint_every_s=1e9,
        progress=False,
        run_dir=str(tmp_path / name),
        buffer_size=5000,
    )
    cfg.update(kw)
    return replace(preset(base), **cfg)
