"""The training loop reports through callbacks (pd_core.dqn.loop) and trains on demonstrations
prepared before the trainer exists (pd_core.dqn.demo_file.prepare_demonstrations)."""

from __future__ import annotations

import csv
from typing import Any

import torch
from train_configs import small_config

from pd_core.dqn.demo_file import DEMO_FILE, prepare_demonstrations
from pd_core.dqn.loop import Callback, Episode
from pd_core.dqn.train import Trainer


class Recorder(Callback):
    def __init__(self) -> None:
        self.calls: list[str] = []
        self.episodes: list[Episode] = []
        self.evals: list[dict[str, float]] = []
        self.summary: dict[str, Any] = {}

    def on_start(self, run: Any) -> None:
        self.calls.append("start")

    def on_episode(self, run: Any, episode: Episode) -> None:
        self.episodes.append(episode)

    def on_eval(self, run: Any, ev: dict[str, float], wall_s: float) -> None:
        self.evals.append(ev)

    def on_end(self, run: Any, summary: dict[str, Any]) -> None:
        self.calls.append("end")
        self.summary = summary


def _weights(tr: Trainer) -> list[torch.Tensor]:
    return [v.clone() for v in tr.agent.q.state_dict().values()]


def test_a_callback_sees_every_episode_and_evaluation_and_changes_no_weight(tmp_path):
    kw = dict(seed=6, eval_every_updates=40, eval_episodes=4)
    plain = Trainer(small_config(tmp_path, "plain", **kw), quiet=True)
    plain.run()
    rec = Recorder()
    watched = Trainer(small_config(tmp_path, "watched", **kw), quiet=True)
    summary = watched.run([rec])
    assert rec.calls == ["start", "end"] and rec.summary == summary
    assert [e.episode for e in rec.episodes] == list(range(1, summary["episodes"] + 1))
    with (tmp_path / "watched" / "episodes.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert [int(r["landed"]) for r in rows] == [e.landed for e in rec.episodes]
    with (tmp_path / "watched" / "evals.csv").open() as fh:
        evals = list(csv.DictReader(fh))
    assert len(rec.evals) == len(evals) >= 3  # 120 updates, one every 40 (and at the end)
    for a, b in zip(_weights(plain), _weights(watched), strict=True):
        assert torch.equal(a, b)


def test_demonstrations_prepared_first_train_as_those_built_by_the_trainer(tmp_path):
    cfg = small_config(tmp_path, "first", seed=7)
    demos = prepare_demonstrations(cfg, tmp_path / "first")
    assert demos.memory is not None and demos.path == tmp_path / "first" / DEMO_FILE
    assert demos.path.is_file() and demos.seconds > 0
    first = Trainer(cfg, tmp_path / "first", quiet=True, demos=demos)
    first.run()
    inside = Trainer(small_config(tmp_path, "inside", seed=7), quiet=True)
    inside.run()
    assert (tmp_path / "inside" / DEMO_FILE).is_file()
    for a, b in zip(_weights(first), _weights(inside), strict=True):
        assert torch.equal(a, b)
