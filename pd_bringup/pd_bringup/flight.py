"""A flight client: one node that resets the simulator, asks the OCP, and follows an episode.

Used by pd_demo (and usable from a notebook): a `RosSession` (its own context and executor, spun
in short slices) that keeps every state, command and result it hears.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from pd_interfaces.msg import EpisodeResult, LanderState, ThrustCommand
from pd_ros_common import diagnostics, names, qos
from pd_ros_common.clients import ocp_client, reset_client
from pd_ros_common.convert import (
    from_vec3,
    ocp_request,
    ocp_trajectory,
    reset_request,
    state_from_msg,
    state_vector,
)
from pd_ros_common.session import RosSession


class FlightError(RuntimeError):
    """The stack did not answer in time or refused."""


class FlightClient(RosSession):
    """States, commands and results of the stack in `namespace`; reset and OCP clients."""

    def __init__(self, domain_id: int | None = None, namespace: str = "/") -> None:
        super().__init__("pd_flight_client", domain_id, namespace)
        self.states: list[LanderState] = []
        self.commands: list[ThrustCommand] = []
        self.results: list[EpisodeResult] = []
        sub = self.node.create_subscription
        sub(LanderState, names.STATE_TOPIC, self.states.append, qos.LOOP_SUB_QOS)
        sub(ThrustCommand, names.COMMAND_TOPIC, self.commands.append, qos.LOOP_SUB_QOS)
        sub(EpisodeResult, names.EPISODE_TOPIC, self.results.append, qos.EPISODE_QOS)
        self.diagnostics = diagnostics.Listener(self.node)
        self.reset_cli = reset_client(self.node)
        self.ocp_cli = ocp_client(self.node)  # the depth a burst of requests needs

    # ------------------------------------------------------------------ calls
    def call(self, client: Any, request: Any, timeout_s: float) -> Any:
        future = client.call_async(request)
        if not self.spin_until(future.done, timeout_s):
            raise FlightError(f"{client.srv_name}: no answer within {timeout_s:g} s")
        return future.result()

    def stack_ready(self, recorder: bool = True) -> bool:
        """Both services up, and every topic the flight needs delivered to all its readers:
        the simulator's and the policy's writers report (/diagnostics `readers <topic>`) that
        they have matched this client, each other and, with `recorder`, a recorder of every
        topic. A reliable, volatile writer sends only to the readers it has matched: without
        this a recorder started beside the stack misses the first messages."""
        rec = int(recorder)
        need = {
            names.STATE_TOPIC: 2 + rec,  # policy, this client
            names.COMMAND_TOPIC: 2 + rec,  # simulator, this client
            names.EPISODE_TOPIC: 1 + rec,  # this client
            names.GUIDANCE_TOPIC: rec,
            names.ODOM_TOPIC: rec,
        }
        return (
            self.reset_cli.service_is_ready()
            and self.ocp_cli.service_is_ready()
            and self.readers_at_least(need)
        )

    def readers_at_least(self, need: dict[str, int]) -> bool:
        """The writer of each of `need`'s (relative) topics reports at least that many matched
        readers in its latest /diagnostics."""
        return self.reported_at_least("readers", need)

    def reported_at_least(self, key: str, need: dict[str, int]) -> bool:
        """Some node's latest /diagnostics has `<key> <topic>` >= n for each (relative) topic."""
        resolve = self.node.resolve_topic_name
        return all(self.diagnostics.highest(f"{key} {resolve(t)}") >= n for t, n in need.items())

    def recorded_at_least(self, need: dict[str, int]) -> bool:
        """A recorder reports (/diagnostics `messages <topic>`) at least `need[topic]` messages
        written of each (relative) topic."""
        return self.reported_at_least("messages", need)

    def recorded_all(self) -> bool:
        """A recorder reports (its /diagnostics `messages <topic>`, written to the bag) at least
        the states and commands this client heard, and a guidance status for every command.
        The recorder reads other writers than this client, and under load its last messages
        arrive later: stop it only once this holds."""
        n_cmd = len(self.commands)
        need = {
            names.STATE_TOPIC: len(self.states),
            names.COMMAND_TOPIC: n_cmd,
            names.GUIDANCE_TOPIC: n_cmd,
        }
        return self.reported_at_least("messages", need)

    # ------------------------------------------------------------------ the flight
    def reset(self, seed: int, state: np.ndarray | None = None) -> tuple[int, np.ndarray]:
        """(episode, initial state) of a new episode, as the simulator reports it."""
        resp = self.call(self.reset_cli, reset_request(state, seed), 10.0)
        if not resp.success:
            raise FlightError(f"{names.RESET_SERVICE} refused: {resp.message}")
        return resp.episode, state_vector(resp.position, resp.velocity, resp.mass)

    def solve_ocp(self, state: np.ndarray, timeout_s: float = 120.0, **fields: Any) -> Any:
        return self.call(self.ocp_cli, ocp_request(state, **fields), timeout_s)

    def result_of(
        self, episode: int, timeout_s: float, check: Callable[[], None] | None = None
    ) -> EpisodeResult:
        """The episode's result, once it and all its states have arrived."""
        if not self.spin_until(lambda: self._result(episode) is not None, timeout_s, check):
            raise FlightError(f"episode {episode} did not end within {timeout_s:g} s")
        result = self._result(episode)
        # The result comes from another writer than the states: let the last ones arrive.
        self.spin_until(lambda: len(self.trajectory(episode)[0]) > result.steps, 5.0)
        return result

    def _result(self, episode: int) -> EpisodeResult | None:
        return next((r for r in self.results if r.episode == episode), None)

    def trajectory(self, episode: int) -> tuple[np.ndarray, np.ndarray]:
        """(states (N+1, 7) by step, thrust (N, 3) by step with NaN where no command was heard)."""
        by_step = {s.step: s for s in self.states if s.episode == episode}
        states = np.array([state_from_msg(by_step[k]) for k in sorted(by_step)]).reshape(-1, 7)
        cmds = {c.step: c for c in self.commands if c.episode == episode}
        n = max(len(states) - 1, 0)
        thrust = np.array(
            [from_vec3(cmds[k].thrust) if k in cmds else [np.nan] * 3 for k in range(n)]
        )
        return states, thrust.reshape(-1, 3)

    @staticmethod
    def ocp_arrays(response: Any) -> dict[str, np.ndarray] | None:
        return ocp_trajectory(response) if response is not None and response.success else None
