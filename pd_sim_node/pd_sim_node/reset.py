"""sim/reset of pd_sim_node (pd_interfaces/srv/ResetEpisode): start a new episode on request.

Contract: a request is refused, with a reason in `message` and a warning logged, when
`pd_core.sim_pacing.ResetGate` refuses it (the node is not active; it names another lander,
answered `REFUSE_DELAY_S` late so that lander's own answer reaches the client first; it names
none while another lander is heard) or when the simulator refuses its initial state or seed.
Otherwise the episode starts (from the request's state with `use_initial_state`, else Table 3;
`seed` >= 0 reseeds, -1 continues the RNG) and waits for its first command as one started at
start-up does. Every answer carries this node's `lander_id`; a success carries the episode
number and its initial state.

Mechanism: the service has a callback group of its own and its handler is a coroutine that
waits out the refusal delay on a one-shot timer in another (reentrant) group, so neither the
commands nor the clock are held meanwhile.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable

import numpy as np
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.task import Future

from pd_core.sim_pacing import ResetGate
from pd_interfaces.srv import ResetEpisode
from pd_ros_common import names, qos
from pd_ros_common.convert import state_vector, vec3
from pd_ros_common.lifecycle import ManagedNode

# start(initial state or None, seed or None) -> (episode, its initial state); ValueError passes
Start = Callable[[np.ndarray | None, int | None], tuple[int, np.ndarray]]


class ResetService:
    """The sim/reset service of `node`: `start` starts an episode, `episode()` is the current
    episode number (0 before a simulator), `others()` the other landers heard."""

    def __init__(
        self,
        node: ManagedNode,
        gate: ResetGate,
        start: Start,
        episode: Callable[[], int],
        others: Callable[[], Iterable[str]],
    ) -> None:
        self._node = node
        self._gate = gate
        self._start = start
        self._episode = episode
        self._others = others
        self._sleep_group = ReentrantCallbackGroup()
        self.service = node.create_service(
            ResetEpisode,
            names.RESET_SERVICE,
            self._on_reset,
            qos_profile=qos.SERVICE_QOS,
            callback_group=MutuallyExclusiveCallbackGroup(),
        )

    async def _on_reset(
        self, request: ResetEpisode.Request, response: ResetEpisode.Response
    ) -> ResetEpisode.Response:
        response.lander_id = self._gate.lander_id
        why, delay_s = self._gate.judge(
            self._node.refusal(), request.lander_id, time.monotonic(), self._others
        )
        if delay_s > 0:
            await self._sleep(delay_s)
        if why is None:
            state = None
            if request.use_initial_state:
                state = state_vector(request.position, request.velocity, request.mass)
            seed = int(request.seed) if request.seed >= 0 else None
            try:
                episode, init = self._start(state, seed)
            except ValueError as exc:
                why = f"reset refused: {exc}"
        if why is not None:
            response.success = False
            response.message = why
            response.episode = self._episode()
            self._node.get_logger().warning(why)
            return response
        response.success = True
        response.message = f"episode {episode} started"
        response.episode = episode
        response.position = vec3(init[0:3])
        response.velocity = vec3(init[3:6])
        response.mass = float(init[6])
        return response

    async def _sleep(self, seconds: float) -> None:
        """Wait without blocking the executor (a one-shot timer completes a future)."""
        done: Future = Future()

        def fire() -> None:
            timer.cancel()
            if not done.done():
                done.set_result(None)

        timer = self._node.create_timer(seconds, fire, callback_group=self._sleep_group)
        try:
            await done
        finally:
            self._node.destroy_timer(timer)
