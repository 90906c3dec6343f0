"""`Runtime`: what flies. A network (or any controller) behind the runtime layer, one entry point.

Each step, for each lander (row):

1. **Predict** (`pd_core.runtime.latency`): the state decided on is the observed one carried
   through the commands still in the actuation pipeline, with the delay and the thrust matrix
   identified in flight, starting from the navigation filter's estimate where the navigation is
   noisy (`pd_core.runtime.navfilter`).
2. **Propose**: the network's greedy action (or the controller's) on that state.
3. **Rules** (`pd_core.runtime.rules`): handover to the ZEM/ZEV-vernier fallback, braking
   limit, touchdown guard.
4. **Record**: the command issued goes into the pipeline memory; the step's `Decision` says who
   decided, and `counts` adds it to its source.

A `Runtime` built with `RuntimeConfig.off()` flies the actor alone. The node, `pd-eval`,
campaigns and tests all fly a policy file through this class (`load_policy`); `bare_action` is
the network alone and says so. Imports numpy only.
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from pd_core.actions import DEFAULT_ACTIONS, ActionSpace
from pd_core.runtime.config import RuntimeConfig
from pd_core.runtime.decision import SOURCES, Decision, Decisions
from pd_core.runtime.latency import LatencyCompensator
from pd_core.runtime.rules import apply_rules, delivered_fraction
from pd_core.state import check_state
from pd_core.teachers.zemzev import ZemZevController

_ROW0 = np.zeros(1, dtype=np.int64)


class Actor(Protocol):
    def act_batch(self, states: np.ndarray) -> np.ndarray: ...


class Runtime:
    """An actor behind the runtime layer; see the module docstring."""

    def __init__(
        self,
        actor: Actor,
        config: RuntimeConfig,
        space: ActionSpace = DEFAULT_ACTIONS,
        name: str = "",
        metadata: dict[str, Any] | None = None,
    ) -> None:
        self.actor = actor
        self.config = config
        self.actions = space
        self.name = name or getattr(actor, "name", "actor")
        self.metadata = metadata or {}
        """the policy file's metadata (empty for a controller)"""
        self.fallback = ZemZevController(config.fallback, space)
        memory = config.latency.max_delay_steps > 0 or config.nav_filter.enabled
        self.latency = LatencyCompensator(config.latency, config.nav_filter) if memory else None
        """the prediction stage's memory (None: decide on the observed state)"""
        self.counts = dict.fromkeys(SOURCES, 0)
        """steps decided by each source since construction (`Decision.source`)"""

    def begin_episodes(self, n: int) -> None:
        """Rows 0..n-1 start new episodes (their memory is cleared)."""
        if self.latency is not None:
            self.latency.reset(n)

    def begin_episode(self) -> None:
        """The one lander flown by `step` starts a new episode."""
        self.begin_episodes(1)

    def step_rows(self, states: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, Decisions]:
        """(actions (B,), their decisions) for the observed states (B, 7) of rows (B,)."""
        observed = check_state(states).reshape(-1, 7)
        rows = np.asarray(rows, dtype=np.int64)
        lat = self.latency
        if lat is None:
            decided, scale = observed, None
        else:
            decided = lat.predict(observed, rows)
            scale = lat.vertical_thrust_scale(rows)
        proposed = np.asarray(self.actor.act_batch(decided), dtype=np.int64).reshape(-1)
        actions, source = apply_rules(
            proposed, decided, self.actions, self.config.rules, self.fallback, scale
        )
        if lat is not None:
            lat.record(rows, self.actions.table_n[actions])
        n = len(rows)
        for k, c in enumerate(np.bincount(source, minlength=len(SOURCES))):
            self.counts[SOURCES[k]] += int(c)
        return actions, Decisions(
            actions,
            proposed,
            source,
            np.zeros(n, dtype=np.int64) if lat is None else lat.delay_steps[rows].copy(),
            delivered_fraction(scale, n, self.config.rules),
            np.zeros(n, dtype=bool) if lat is None or lat.nav is None else lat.nav.engaged[rows],
        )

    def act_rows(self, states: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """Actions (B,) for the observed states (B, 7) of rows (B,) (`step_rows` without the
        decisions: `pd_core.experiments.evaluate.fly_episodes`)."""
        return self.step_rows(states, rows)[0]

    def step(self, observation: np.ndarray) -> tuple[int, Decision]:
        """(action, its decision) for the next observed state (7,) of the one lander flown."""
        actions, decisions = self.step_rows(np.reshape(observation, (1, 7)), _ROW0)
        return int(actions[0]), decisions[0]

    def bare_action(self, observation: np.ndarray) -> int:
        """The network's (or controller's) own action on an observed state (7,): no prediction,
        no rule, no memory. Not what flies."""
        return int(self.actor.act_batch(check_state(observation).reshape(1, 7))[0])

    def thrust(self, action: int) -> np.ndarray:
        """Thrust (3,) in N of an action index; ValueError if out of range."""
        return self.actions.thrust(int(action))

    @property
    def changed(self) -> int:
        """Steps on which the layer changed the actor's action (since construction)."""
        return sum(v for k, v in self.counts.items() if k != SOURCES[0])

    def describe(self) -> str:
        """One phrase on what the layer decided for row 0 (the policy node's statistics)."""
        steps = sum(self.counts.values())
        rules = ", ".join(f"{k} {v}" for k, v in self.counts.items() if k != SOURCES[0])
        out = f"layer changed {self.changed} of {steps} actions ({rules})"
        if self.latency is not None:
            out += "; " + self.latency.describe(0)
        return out
