"""Recent training outcomes per dispersion scenario, for failure-weighted domain randomisation.

With `scenario_sampling = "failures"` the training envs draw each new episode's scenario with
`pd_core.dispersions.failure_weights` of the last `window` training episodes of every scenario:
where the policy already lands it keeps a floor share, where it fails it trains more.
"""

from __future__ import annotations

import json
from collections import deque

import numpy as np

from pd_core.dispersions import failure_weights


class ScenarioOutcomes:
    """The last `window` outcomes (landed or not) of each of `n` scenarios."""

    def __init__(self, n: int, window: int, uniform_share: float) -> None:
        if n < 1 or window < 1:
            raise ValueError(f"need n >= 1 scenarios and window >= 1, got {n}, {window}")
        self.uniform_share = uniform_share
        self.recent: list[deque[int]] = [deque(maxlen=window) for _ in range(n)]

    def record(self, scenario: int, landed: bool) -> None:
        self.recent[scenario].append(int(landed))

    def failure_rates(self) -> np.ndarray:
        """Raw failure rate of each scenario's window (NaN where none has ended yet)."""
        return np.array([1.0 - np.mean(r) if r else np.nan for r in self.recent])

    def probs(self) -> np.ndarray:
        episodes = np.array([len(r) for r in self.recent])
        failures = episodes - np.array([sum(r) for r in self.recent])
        return failure_weights(failures, episodes, self.uniform_share)

    def to_json(self) -> str:
        return json.dumps([list(r) for r in self.recent])

    def load_json(self, text: str) -> None:
        saved = json.loads(text)
        if len(saved) != len(self.recent):
            raise ValueError(f"outcomes of {len(saved)} scenarios saved, {len(self.recent)} here")
        for r, s in zip(self.recent, saved, strict=True):
            r.clear()
            r.extend(int(x) for x in s)
