"""Managed (lifecycle) nodes of the stack: one base class that says, for every node alike, what
each transition does, and a plain `lifecycle_msgs` client for tools, the manager and tests.

A node subclasses `ManagedNode` and writes four methods; the base turns them into the
transition callbacks of `rclpy.lifecycle.LifecycleNode` and logs one line per transition:

- configure, `_configure() -> str`: validate, load what is slow (model, solver process, first
  episode), make lifecycle publishers, subscriptions and timers; returns the "ready" line. An
  error of a kind in `expected_errors` is a FAILURE (back to unconfigured), said in one line.
- activate, `_activate() -> str`: the node's publishers come on (the base), then its work resumes.
- deactivate, `_deactivate() -> str`: work is held (the simulator keeps its step), then the
  publishers go off.
- cleanup, `_release() -> str`: what configure took is released; what it made with `own()` is
  destroyed.
- shutdown: deactivate and release as needed; on_error: release, back to unconfigured.

`active` is the flag callbacks look at. `/diagnostics` is made in the constructor and answers
in every state; the key `lifecycle state` says which.

Invalid transitions (configure twice, activate while unconfigured, an unknown id or label) are
answered `success: false` and logged with the transitions valid from the current state; they
never kill the node. `start_up(node)` is what `autostart` (`AUTOSTART`) does: configure and
activate, the failure of an expected kind left to the caller to report in one line.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import lifecycle_msgs.msg
import lifecycle_msgs.srv
from rclpy.client import Client
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.service import Service
from rclpy.subscription import Subscription
from rclpy.timer import Timer

from pd_core import lifecycle as lc
from pd_ros_common import diagnostics
from pd_ros_common.params import ParameterError

SUCCESS = TransitionCallbackReturn.SUCCESS
FAILURE = TransitionCallbackReturn.FAILURE
ERROR = TransitionCallbackReturn.ERROR

AUTOSTART = (
    True,
    "Lifecycle: take the node alone to active at start-up (configure, then activate), as "
    "`ros2 run` users expect. false = wait unconfigured for a lifecycle manager "
    "(pd_lifecycle_manager) or a lifecycle_msgs/ChangeState request.",
)

# service and topic names of a managed node `<node>` (rcl_lifecycle's)
CHANGE_STATE = "{}/change_state"
GET_STATE = "{}/get_state"
GET_AVAILABLE_STATES = "{}/get_available_states"
GET_AVAILABLE_TRANSITIONS = "{}/get_available_transitions"
TRANSITION_EVENT = "{}/transition_event"


class ManagedNode(LifecycleNode):
    """A lifecycle node whose transitions are `_configure`, `_activate`, `_deactivate` and
    `_release` (see the module's table); `active` tells callbacks whether to work."""

    # configure errors reported in one line (FAILURE); anything else is an ERROR (on_error)
    expected_errors: tuple[type[BaseException], ...] = (ParameterError,)

    def __init__(self, node_name: str, **kwargs: Any) -> None:
        self.active = False
        self.configured = False
        self.failure: BaseException | None = None  # the last configure's error
        self.quiet = False  # start_up: the caller reports a failed configure itself
        self._owned: list[Any] = []
        self._transition_lock = threading.Lock()
        super().__init__(node_name, **kwargs)
        service = self._service_change_state
        service.callback = self._guard_change_state(service.callback)

    # ------------------------------------------------------------------ for subclasses
    def _configure(self) -> str:
        return "configured"

    def _activate(self) -> str:
        return "active"

    def _deactivate(self) -> str:
        return "inactive"

    def _release(self) -> str:
        return "nothing to release"

    def own(self, entity: Any) -> Any:
        """Record a publisher, subscription, timer, service or client made by `_configure`:
        cleanup destroys it."""
        self._owned.append(entity)
        return entity

    @property
    def state_id(self) -> int:
        return int(self._state_machine.current_state[0])

    @property
    def state_label(self) -> str:
        return str(self._state_machine.current_state[1])

    def managed_report(
        self, report: Callable[[], diagnostics.Report]
    ) -> Callable[[], diagnostics.Report]:
        """`report` for /diagnostics in every state: the node's own once configured, its
        lifecycle state first; a bare one saying the state before."""

        def in_any_state() -> diagnostics.Report:
            label = self.state_label
            if not self.configured:
                r = diagnostics.Report(ok_message=label)
                r.values = {"lifecycle state": label}
                return r
            r = report()
            r.values = {"lifecycle state": label, **r.values}
            if not self.active:
                r.ok_message = label
            return r

        return in_any_state

    def refusal(self) -> str:
        """Why a request is refused in the current state ("" when active)."""
        return "" if self.active else f"{self.get_name()} is {self.state_label}"

    # ------------------------------------------------------------------ transitions
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        with self._transition_lock:
            try:
                ready = self._configure()
            except Exception as exc:
                self.failure = exc
                self._release_quietly()
                expected = isinstance(exc, self.expected_errors)
                if not self.quiet:
                    why = str(exc) if expected else repr(exc)
                    self.get_logger().error(f"configure failed: {why}")
                return FAILURE if expected else ERROR
            self.failure = None
            self.configured = True
        self.get_logger().info(ready)
        return SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        with self._transition_lock:
            ret = super().on_activate(state)  # lifecycle publishers on
            if ret != SUCCESS:
                return ret
            self.active = True
            what = self._activate()
        self.get_logger().info(f"active: {what}")
        return SUCCESS

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        with self._transition_lock:
            what = self._deactivate_now()
        self.get_logger().info(f"inactive: {what}")
        return SUCCESS

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        with self._transition_lock:
            what = self._release_now()
        self.get_logger().info(f"cleaned up: {what}")
        return SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        with self._transition_lock:
            done = []
            if self.active:
                done.append(self._deactivate_now())
            if self.configured:
                done.append(self._release_now())
        self.get_logger().info(f"shut down from {state.label}: {'; '.join(done) or 'nothing held'}")
        return SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        with self._transition_lock:
            self.active = False
            what = self._release_quietly()
        self.get_logger().error(f"error while leaving {state.label}: {what}; back to unconfigured")
        return SUCCESS

    def _deactivate_now(self) -> str:
        self.active = False
        what = self._deactivate()
        super().on_deactivate(LifecycleState("active", lc.ACTIVE))  # publishers off
        return what

    def _release_now(self) -> str:
        what = self._release()
        self._destroy_owned()
        self.configured = False
        return what

    def _release_quietly(self) -> str:
        try:
            return self._release_now()
        except Exception as exc:  # a half-made configuration: release what there is
            self._destroy_owned()
            self.configured = False
            return f"released with an error ({exc!r})"

    def _destroy_owned(self) -> None:
        owned, self._owned = self._owned, []
        for e in reversed(owned):
            if isinstance(e, Publisher):
                self.destroy_lifecycle_publisher(e)  # type: ignore[arg-type]
            elif isinstance(e, Subscription):
                self.destroy_subscription(e)
            elif isinstance(e, Timer):
                self.destroy_timer(e)
            elif isinstance(e, Service):
                self.destroy_service(e)
            elif isinstance(e, Client):
                self.destroy_client(e)

    # ------------------------------------------------------------------ requests
    def _guard_change_state(self, callback: Callable[..., Any]) -> Callable[..., Any]:
        """rclpy's change_state handler, answering and logging a refused transition."""

        def on_change_state(
            request: lifecycle_msgs.srv.ChangeState.Request,
            response: lifecycle_msgs.srv.ChangeState.Response,
        ) -> lifecycle_msgs.srv.ChangeState.Response:
            before = self.state_id
            t = request.transition
            if t.label:
                ids = [x for x, lb in lc.TRANSITION_LABELS.items() if lb == t.label]
            else:
                ids = [t.id] if t.id in lc.TRANSITION_LABELS else []
            asked = t.label or (lc.transition_label(t.id) if ids else str(t.id))
            if not any(lc.valid(before, x) for x in ids):
                response.success = False
                what = "transition" if ids else "unknown transition"
                self.get_logger().warning(
                    f"{what} {asked!r} refused in state {lc.state_label(before)}: valid are "
                    f"{', '.join(sorted(set(lc.valid_from(before)))) or 'none'}"
                )
                return response
            try:
                return callback(request, response)
            except Exception as exc:  # never let a request kill the node
                response.success = False
                self.get_logger().error(f"transition {asked!r} failed: {exc!r}")
                return response

        return on_change_state

    def finish(self) -> None:
        """Shutdown transition from whatever primary state (the process is stopping)."""
        if self.state_id in lc.SHUTDOWN_FROM:
            self._change(lc.SHUTDOWN_FROM[self.state_id])

    def _change(self, transition: int) -> TransitionCallbackReturn:
        return {
            lc.CONFIGURE: self.trigger_configure,
            lc.ACTIVATE: self.trigger_activate,
            lc.DEACTIVATE: self.trigger_deactivate,
            lc.CLEANUP: self.trigger_cleanup,
        }.get(transition, self.trigger_shutdown)()


def start_up(node: ManagedNode) -> BaseException | None:
    """`autostart`: configure, then activate. The configure error (None if it went well);
    the node logs nothing of it (the caller says it in one line)."""
    node.quiet = True
    try:
        if node.trigger_configure() != SUCCESS:
            return node.failure or RuntimeError("configure failed")
    finally:
        node.quiet = False
    node.trigger_activate()
    return None


class LifecycleClient:
    """The standard services of one managed node, as a plain `lifecycle_msgs` client
    (`<node>/change_state`, `get_state`, `get_available_states`, `get_available_transitions`).
    Calls are asynchronous (futures); the caller spins."""

    def __init__(self, node: Node, target: str) -> None:
        self.target = target
        self.change_state = node.create_client(
            lifecycle_msgs.srv.ChangeState, CHANGE_STATE.format(target)
        )
        self.get_state = node.create_client(lifecycle_msgs.srv.GetState, GET_STATE.format(target))
        self.get_available_states = node.create_client(
            lifecycle_msgs.srv.GetAvailableStates, GET_AVAILABLE_STATES.format(target)
        )
        self.get_available_transitions = node.create_client(
            lifecycle_msgs.srv.GetAvailableTransitions, GET_AVAILABLE_TRANSITIONS.format(target)
        )

    def ready(self) -> bool:
        return self.change_state.service_is_ready() and self.get_state.service_is_ready()

    def request_change(self, transition: int = 0, label: str = "") -> Any:
        req = lifecycle_msgs.srv.ChangeState.Request()
        req.transition = lifecycle_msgs.msg.Transition(id=transition, label=label)
        return self.change_state.call_async(req)

    def request_state(self) -> Any:
        return self.get_state.call_async(lifecycle_msgs.srv.GetState.Request())
