"""The Gymnasium face of one lander: `PoweredDescentEnv` is `pd_core.lander.Lander` as a
`gymnasium.Env` (spaces, `check_env`, Gymnasium's seeding). The step function and the episode
logic live in `pd_core.lander`; the batched env is `pd_core.vector_env`.
"""

from __future__ import annotations

from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from pd_core.lander import Lander

# Scaled states of anything `check_state` accepts lie well inside +-1e4.
OBSERVATION_SPACE = spaces.Box(-1e4, 1e4, shape=(7,), dtype=np.float32)


class PoweredDescentEnv(Lander, gym.Env):
    """`Lander` as a Gymnasium env: Discrete(147) actions, a Box of scaled states, and
    `reset(seed=...)` through `gymnasium.Env.reset` (its `np_random`)."""

    metadata: ClassVar[dict[str, Any]] = {"render_modes": []}

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        """As `Lander(...)`; adds the Gymnasium spaces."""
        Lander.__init__(self, *args, **kwargs)
        self.action_space = spaces.Discrete(self.actions.n)
        self.observation_space = OBSERVATION_SPACE

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        gym.Env.reset(self, seed=seed)
        return self._start(self.np_random, options)
