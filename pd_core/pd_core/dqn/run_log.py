"""The CSV logs of a training run folder (appended to across resumed segments).

episodes.csv has one row per finished training episode (Fig. 5), metrics.csv the losses, epsilon
and running return/success every 10 s, evals.csv the periodic greedy evaluations against wall time.
"""

from __future__ import annotations

import csv
import time
from pathlib import Path
from typing import Any

from pd_core.dqn.config import TrainConfig

EPISODE_COLUMNS = (
    "episode",
    "wall_s",
    "env_steps",
    "updates",
    "return",
    "landed",
    "fuel_kg",
    "k_velocity_mps",
    "epsilon",
)
METRIC_COLUMNS = (
    "wall_s",
    "env_steps",
    "updates",
    "episodes",
    "epsilon",
    "loss",
    "td_loss",
    "margin_loss",
    "q_mean",
    "return_100",
    "success_100",
)
EVAL_COLUMNS = (
    "wall_s",
    "updates",
    "episodes",
    "success_rate",
    "soft_landing_rate",
    "fuel_median",
    "pos_median",
    "kvel_min",
    "mean_return",
)


class CsvLog:
    """An append-only CSV file; the header is written only when the file is new."""

    def __init__(self, path: Path, header: tuple[str, ...]) -> None:
        new = not path.exists()
        self.f = path.open("a", newline="")
        self.w = csv.writer(self.f)
        if new:
            self.w.writerow(header)

    def row(self, *values: Any) -> None:
        self.w.writerow([f"{v:.6g}" if isinstance(v, float) else v for v in values])

    def flush(self) -> None:
        self.f.flush()

    def close(self) -> None:
        self.f.close()


class RunLogs:
    """The three logs of a run folder, opened together and flushed together."""

    def __init__(self, run_dir: Path) -> None:
        self.episodes = CsvLog(run_dir / "episodes.csv", EPISODE_COLUMNS)
        self.metrics = CsvLog(run_dir / "metrics.csv", METRIC_COLUMNS)
        self.evals = CsvLog(run_dir / "evals.csv", EVAL_COLUMNS)

    def flush(self) -> None:
        for log in (self.episodes, self.metrics, self.evals):
            log.flush()

    def close(self) -> None:
        for log in (self.episodes, self.metrics, self.evals):
            log.close()


def run_folder(cfg: TrainConfig) -> Path:
    """`cfg.run_dir`, or runs/<preset>__<seed>__<time> (CleanRL's naming)."""
    if cfg.run_dir:
        return Path(cfg.run_dir)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    return Path("runs") / f"{cfg.preset}__{cfg.seed}__{stamp}"
