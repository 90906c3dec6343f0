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
campaigns, benches and tests all build what flies with `pd_core.runtime.build` (a policy file
through `load_policy`, or a controller); `begin_episode(s)` starts the layer's and the actor's
memory afresh, and `bare_action` is the network alone, says so, and changes nothing.

Imports numpy, and numba for the layer's compiled arithmetic (`pd_core.runtime.kernels`,
compiled or loaded from numba's cache once per process when the first `Runtime` is built):
steps 1 and 3-4 are one compiled call each (`kernels_step`).
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from pd_core.actions import DEFAULT_ACTIONS, ActionSpace
from pd_core.runtime.config import LatencyConfig, NavFilterConfig, RulesConfig, RuntimeConfig
from pd_core.runtime.decision import SOURCES, Decision, Decisions, changed_count, describe_counts
from pd_core.runtime.kernels_state import NO_PIPELINE, RuleSettings
from pd_core.runtime.kernels_step import after_actor
from pd_core.runtime.latency import LatencyCompensator
from pd_core.runtime.network import NumpyQNetwork, observed_states
from pd_core.runtime.rules import rule_settings
from pd_core.teachers.zemzev import ZemZevController

_ROW0 = np.zeros(1, dtype=np.int64)
_NO_SCALE = np.ones(0)


def _warm_up(fallback: ZemZevController) -> None:
    """Compile every kernel a decision calls (or load it from numba's cache next to
    `pd_core.runtime.kernels`), once per process: a policy loaded at start-up decides at full
    speed from its first step."""
    global _WARM
    if _WARM:
        return
    s = np.array([[0.0, 0.0, 1000.0, 0.0, 0.0, -50.0, 2000.0]])
    rows = np.zeros(1, dtype=np.int64)
    lat = LatencyCompensator(LatencyConfig(), NavFilterConfig())
    decided, scale = lat.predict_scaled(s, rows)
    proposed = np.zeros(1, dtype=np.int64)
    settings = rule_settings(RulesConfig(), DEFAULT_ACTIONS)
    for memory in (lat, None):
        rules_and_record(settings, fallback, proposed, decided, scale, rows, memory)
    tiny = {"net.0.weight": np.zeros((1, 13)), "net.0.bias": np.zeros(1)}
    NumpyQNetwork(tiny, np.ones(7), near_pad=True).act_batch(s)
    _WARM = True


def rules_and_record(
    settings: RuleSettings,
    fallback: ZemZevController,
    proposed: np.ndarray,
    decided: np.ndarray,
    scale: np.ndarray,
    rows: np.ndarray,
    memory: LatencyCompensator | None,
) -> tuple[np.ndarray, Decisions]:
    """`pd_core.runtime.rules.decide` on the actions proposed (B,) for the states decided on
    (B, 7) of rows (B,), counting on the vertical thrust scale (B,) (ignored without memory),
    and `memory.record` of the actions flown (if memory): one compiled call
    (`kernels_step.after_actor`), two where the fallback takes over a row."""
    n = len(proposed)
    actions = np.empty(n, dtype=np.int64)
    hand = np.empty(n, dtype=bool)
    source = np.empty(n, dtype=np.uint8)
    frac = np.empty(n)
    limit = np.empty(n, dtype=np.uint8)
    delay = np.empty(n, dtype=np.int64)
    nav = np.empty(n, dtype=bool)
    pipeline = NO_PIPELINE if memory is None else memory.pipeline()
    head = (proposed, decided, scale, rows, tuple(settings), pipeline)  # plain: kernels_step
    if not after_actor(*head, False, actions, hand, source, frac, limit, delay, nav):
        actions[hand] = fallback.act_batch(decided[hand])
        after_actor(*head, True, actions, hand, source, frac, limit, delay, nav)
    return actions, Decisions(actions, proposed, source, delay, frac, nav, limit)


_WARM = False


class Actor(Protocol):
    """What a `Runtime` flies: `act_batch(states (B, 7)) -> actions (B,)`, the actor's decision
    on the states decided on (it may remember them: an MPC teacher continues its plans).

    An actor with memory also has `begin_episode()` (every lander it flies starts a new
    episode: forget it all) and `propose(states)` (the actions `act_batch` would return,
    changing nothing); every actor of pd_core has both (`NumpyQNetwork`, `ZemZevController`,
    `MPCController`). A memoryless actor may lack them (a wrapper in a test or a bench): the
    runtime then calls nothing at an episode's start and proposes with `act_batch`. An actor
    that plans on the thrust the layer counts on has `takes_thrust_fraction` and
    `take_thrust_fraction(fraction (B,))`, called before each `act_batch` of `step_rows`."""

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
        self._rules = rule_settings(config.rules, space, self.fallback.params)
        memory = config.latency.max_delay_steps > 0 or config.nav_filter.enabled
        self.latency = LatencyCompensator(config.latency, config.nav_filter) if memory else None
        """the prediction stage's memory (None: decide on the observed state)"""
        self.counts = dict.fromkeys(SOURCES, 0)
        """steps decided by each source since construction (`Decision.source`)"""
        _warm_up(self.fallback)

    def begin_episodes(self, n: int) -> None:
        """Rows 0..n-1 start new episodes, and no other row is flown until the next call: the
        layer's memory is n fresh rows and the actor forgets everything (`begin_episode`: an MPC
        teacher drops every plan). The rows then flown (`step_rows`, any subset of 0..n-1 per
        step, as landers finish) keep their memory in the layer by row number; an actor that
        remembers matches its memory to the states it is given (an MPC teacher, by the state
        each plan predicts), so shifting subsets of rows do not mix two landers."""
        if self.latency is not None:
            self.latency.reset(n)
        begin = getattr(self.actor, "begin_episode", None)
        if begin is not None:
            begin()

    def begin_episode(self) -> None:
        """The one lander flown by `step` starts a new episode (`begin_episodes(1)`)."""
        self.begin_episodes(1)

    def step_rows(self, states: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, Decisions]:
        """(actions (B,), their decisions) for the observed states (B, 7) of rows (B,).

        Three calls: the prediction stage (`LatencyCompensator.predict_scaled`, one compiled
        call), the actor, and the rules with the pipeline's record (`rules_and_record`)."""
        rows = np.asarray(rows, dtype=np.int64)
        lat = self.latency
        if lat is None:
            decided, scale = observed_states(states), _NO_SCALE
        else:
            decided, scale = lat.predict_scaled(states, rows)
        if getattr(self.actor, "takes_thrust_fraction", False):
            self.actor.take_thrust_fraction(self._counted_fraction(scale, len(decided)))  # type: ignore[attr-defined]
        proposed = np.ascontiguousarray(self.actor.act_batch(decided), dtype=np.int64).reshape(-1)
        actions, decisions = rules_and_record(
            self._rules, self.fallback, proposed, decided, scale, rows, lat
        )
        source = decisions.source
        n = len(actions)
        counts = self.counts
        if n == 1:
            counts[SOURCES[source[0]]] += 1
        else:
            for k, c in enumerate(np.bincount(source, minlength=len(SOURCES)).tolist()):
                counts[SOURCES[k]] += c
        return actions, decisions

    def _counted_fraction(self, scale: np.ndarray, n: int) -> np.ndarray:
        """The vertical thrust fraction (n,) the rules will count on for each row (as
        `kernels_rules.rules_rows`: the prediction stage's scale clipped to
        [min_measured_thrust, 1] where `measured_thrust`, else 1), for an actor that plans on it
        (`takes_thrust_fraction`, e.g. `MPCParams.layer_thrust_fraction`); read only, the rules
        do not change."""
        r = self.config.rules
        if self.latency is None or not r.measured_thrust or len(scale) != n:
            return np.ones(n)
        return np.clip(scale, r.min_measured_thrust, 1.0)

    def act_rows(self, states: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """Actions (B,) for the observed states (B, 7) of rows (B,) (`step_rows` without the
        decisions: `pd_core.episodes.fly_episodes`)."""
        return self.step_rows(states, rows)[0]

    def step(self, observation: np.ndarray) -> tuple[int, Decision]:
        """(action, its decision) for the next observed state (7,) of the one lander flown."""
        actions, decisions = self.step_rows(np.reshape(observation, (1, 7)), _ROW0)
        return int(actions[0]), decisions[0]

    def bare_action(self, observation: np.ndarray) -> int:
        """The network's (or controller's) own action on an observed state (7,): no prediction,
        no rule, a nominal engine. Not what flies, and no side effect: the layer's memory is not
        read or written and the actor's is not changed (its `propose`: an MPC teacher answers
        on a copy of its plans), so the next `step` decides as if it had not been called."""
        propose = getattr(self.actor, "propose", self.actor.act_batch)
        return int(propose(observed_states(observation))[0])

    def thrust(self, action: int) -> np.ndarray:
        """Thrust (3,) in N of an action index; ValueError if out of range."""
        return self.actions.thrust(int(action))

    @property
    def changed(self) -> int:
        """Steps on which the layer changed the actor's action (since construction)."""
        return changed_count(self.counts)

    def describe(self) -> str:
        """One phrase on what the layer decided for row 0 (the policy node's statistics)."""
        out = "layer " + describe_counts(self.counts)
        if self.latency is not None:
            out += "; " + self.latency.describe(0)
        return out
