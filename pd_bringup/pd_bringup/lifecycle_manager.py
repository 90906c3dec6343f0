"""pd_lifecycle_manager: brings the stack's managed nodes up in order, watches them, and takes the
stack down when one fails or on Ctrl-C (as nav2's lifecycle_manager does).

    pd_lifecycle_manager                               # pd_ocp_node, pd_policy_node, pd_sim_node
    pd_lifecycle_manager --nodes pd_policy_node,pd_sim_node --heartbeat-timeout 3
    pd_lifecycle_manager --ros-args -r __ns:=/vehicle1 # the stack of namespace /vehicle1

1. It waits for each node's lifecycle services, configures every node in list order, then
   activates them in the same order (a node already there is left as it is), printing one line
   per transition: `pd_ocp_node: configure: unconfigured -> inactive (0.42 s)`.
2. It watches the active nodes: each must publish its /diagnostics heartbeat (1 Hz) within
   `--heartbeat-timeout` and answer `get_state` with `active` (two unanswered in a row, 3 s
   each, count as gone). When one fails (it died, hangs, or went to another state), it
   deactivates the others, in reverse order, and says why in one line: `pd_sim_node failed (no
   /diagnostics heartbeat for 5.2 s); deactivated pd_policy_node, pd_ocp_node`. It then keeps
   running, the stack down, until stopped.
3. Ctrl-C or SIGTERM: deactivate, cleanup and shutdown, each in reverse order, then exit: status
   0, or 1 if a node failed or did not come up (2 for a bad command line).

The nodes are started with `-p autostart:=false` (they wait unconfigured); the manager speaks only
the standard `lifecycle_msgs` services, so it manages any managed node. Names resolve in the
manager's namespace. `pd_demo` runs the same `LifecycleManager` in its own process.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from lifecycle_msgs.msg import TransitionEvent
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from pd_core import lifecycle as lc
from pd_ros_common import names, qos, session
from pd_ros_common.cli import UsageError, split_ros_args
from pd_ros_common.lifecycle import TRANSITION_EVENT, LifecycleClient

WATCH_PERIOD_S = 1.0  # get_state of every active node this often
STATE_TIMEOUT_S = 3.0  # a get_state unanswered this long is a miss
STATE_MISSES = 2  # this many misses in a row: the node counts as gone (a busy machine drops one)
SpinUntil = Callable[[Callable[[], bool], float], bool]


class LifecycleManager:
    """Drives the managed `nodes` through `node` (the caller's; it spins it with
    `spin_until(predicate, timeout_s) -> bool`) and says each transition with `say`."""

    def __init__(
        self,
        node: Node,
        spin_until: SpinUntil,
        nodes: Sequence[str] = names.MANAGED_NODES,
        say: Callable[[str], None] = print,
        heartbeat_timeout_s: float = 5.0,
        transition_timeout_s: float = 120.0,
        interrupted: Callable[[], bool] = lambda: False,
    ) -> None:
        self.node = node
        self._spin_until = spin_until
        self.nodes = list(nodes)
        self.say = say
        self.transition_timeout_s = transition_timeout_s
        self.clients = {n: LifecycleClient(node, n) for n in self.nodes}
        self.states = {n: lc.UNKNOWN for n in self.nodes}
        self.heartbeats = lc.Heartbeats(heartbeat_timeout_s)
        self._prefix = {node.resolve_topic_name(n).lstrip("/") + ": ": n for n in self.nodes}
        self.events: dict[str, list[TransitionEvent]] = {n: [] for n in self.nodes}
        self.failure: str | None = None  # the line said when a node failed
        self.interrupted = interrupted  # a stop was asked: a wait cut short is no failure
        self._misses = {n: 0 for n in self.nodes}
        self._next_watch = 0.0
        node.create_subscription(
            DiagnosticArray, names.DIAGNOSTICS_TOPIC, self._on_diagnostics, qos.DIAGNOSTICS_QOS
        )
        for n in self.nodes:
            node.create_subscription(
                TransitionEvent, TRANSITION_EVENT.format(n), self.events[n].append, qos.LOOP_SUB_QOS
            )

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        now = time.monotonic()
        for s in msg.status:
            for prefix, n in self._prefix.items():
                if s.name.startswith(prefix):
                    self.heartbeats.beat(n, now)

    # ------------------------------------------------------------------ requests
    def wait_for_services(self, timeout_s: float) -> list[str]:
        """The nodes whose lifecycle services did not appear within `timeout_s` ([] = all)."""
        self._spin_until(lambda: all(c.ready() for c in self.clients.values()), timeout_s)
        return [n for n, c in self.clients.items() if not c.ready()]

    def get_state(self, name: str, timeout_s: float = STATE_TIMEOUT_S) -> int:
        """The node's primary state (UNKNOWN if get_state is unanswered within `timeout_s`)."""
        future = self.clients[name].request_state()
        if not self._spin_until(future.done, timeout_s) or future.result() is None:
            return lc.UNKNOWN
        return int(future.result().current_state.id)

    def change(self, name: str, transition: int) -> bool:
        """One transition of one node, said in one line; True if it succeeded."""
        before = self.states[name]
        label = lc.transition_label(transition)
        t0 = time.monotonic()
        future = self.clients[name].request_change(transition)
        if not self._spin_until(future.done, self.transition_timeout_s):
            if self.interrupted():
                self.say(f"{name}: {label}: interrupted")
                return False
            self.say(f"{name}: {label}: unanswered within {self.transition_timeout_s:g} s")
            self.states[name] = lc.UNKNOWN
            return False
        ok = bool(future.result() is not None and future.result().success)
        after = self.states[name] = self.get_state(name)
        how = "" if ok else ", FAILED"
        self.say(
            f"{name}: {label}: {lc.state_label(before)} -> {lc.state_label(after)} "
            f"({time.monotonic() - t0:.2f} s{how})"
        )
        if after == lc.ACTIVE:
            self.heartbeats.expect(name, time.monotonic())
        else:
            self.heartbeats.forget(name)
        return ok

    def _go(self, name: str, goal: int) -> str | None:
        """Take `name` to `goal`; why not (None when it got there)."""
        try:
            steps = lc.path(self.states[name], goal)
        except ValueError as exc:
            return str(exc)
        for t in steps:
            if not self.change(name, t):
                return f"{lc.transition_label(t)} failed, it is {lc.state_label(self.states[name])}"
        return None

    # ------------------------------------------------------------------ the stack
    def startup(self) -> bool:
        """Configure every node in order, then activate them in order. On a failure the nodes
        already active are deactivated (one line says why); False."""
        for n in self.nodes:
            self.states[n] = self.get_state(n)
            if self.states[n] == lc.ACTIVE:
                self.heartbeats.expect(n, time.monotonic())
        for n, t in lc.bringup(self.nodes):
            goal = lc.INACTIVE if t == lc.CONFIGURE else lc.ACTIVE
            if self.states[n] == lc.ACTIVE:
                continue
            why = self._go(n, goal)
            if why is not None:
                if not self.interrupted():
                    self.fail(n, why)
                return False
        return True

    def fail(self, name: str, why: str) -> str:
        """Deactivate every other active node, in reverse order; the one line that says so."""
        done = []
        for n in lc.teardown(self.nodes):
            if n != name and self.states[n] == lc.ACTIVE and self.change(n, lc.DEACTIVATE):
                done.append(n)
        self.heartbeats.forget(name)
        self.failure = lc.failure_line(name, why, done)
        self.say(self.failure)
        return self.failure

    def watch(self) -> str | None:
        """Check the active nodes (at most once per WATCH_PERIOD_S): a stale heartbeat, a
        state other than active or STATE_MISSES get_state unanswered in a row take the stack
        down. The failure line, or None (also when a stop cut the check short)."""
        now = time.monotonic()
        if self.failure is not None or now < self._next_watch:
            return None
        self._next_watch = now + WATCH_PERIOD_S
        for n, age in self.heartbeats.overdue(now):
            return self.fail(n, f"no /diagnostics heartbeat for {age:.1f} s")
        watched = [n for n in self.nodes if self.states[n] == lc.ACTIVE]
        futures = {n: self.clients[n].request_state() for n in watched}
        self._spin_until(lambda: all(f.done() for f in futures.values()), STATE_TIMEOUT_S)
        if self.interrupted():
            return None
        for n, f in futures.items():
            if not f.done() or f.result() is None:
                self._misses[n] += 1
                if self._misses[n] < STATE_MISSES:
                    continue
                self.states[n] = lc.UNKNOWN
                waited = STATE_MISSES * STATE_TIMEOUT_S
                return self.fail(n, f"get_state unanswered {STATE_MISSES} times ({waited:g} s)")
            self._misses[n] = 0
            state = int(f.result().current_state.id)
            if state != lc.ACTIVE:
                self.states[n] = state
                return self.fail(n, f"it went {lc.state_label(state)}")
        return None

    def shutdown(self) -> None:
        """Deactivate, cleanup and shutdown, each in reverse order (nodes that answer)."""
        for n in self.nodes:
            if self.states[n] != lc.FINALIZED:
                self.states[n] = self.get_state(n)
        gone = [n for n in self.nodes if self.states[n] == lc.UNKNOWN]
        if gone:
            self.say(f"not answering, left as they are: {', '.join(gone)}")
        for transition, start in (
            (lc.DEACTIVATE, lc.ACTIVE),
            (lc.CLEANUP, lc.INACTIVE),
            (lc.UNCONFIGURED_SHUTDOWN, lc.UNCONFIGURED),
        ):
            for n in lc.teardown(self.nodes):
                if self.states[n] == start:
                    self.change(n, transition)


# ---------------------------------------------------------------------- the executable
def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="pd_lifecycle_manager", description=__doc__.split("\n\n")[0])
    p.add_argument(
        "--nodes",
        default=",".join(names.MANAGED_NODES),
        help="managed nodes, comma-separated, in bring-up order (default: %(default)s)",
    )
    p.add_argument(
        "--heartbeat-timeout",
        type=float,
        default=5.0,
        help="an active node silent on /diagnostics this long (s) has failed (default 5)",
    )
    p.add_argument(
        "--transition-timeout",
        type=float,
        default=120.0,
        help="a transition unanswered this long (s) has failed (default 120: a busy configure)",
    )
    p.add_argument(
        "--service-timeout",
        type=float,
        default=60.0,
        help="wait this long (s) for the nodes' lifecycle services at start (default 60)",
    )
    args = p.parse_args(list(argv))
    args.nodes = [n.strip() for n in args.nodes.split(",") if n.strip()]
    if not args.nodes:
        p.error("--nodes names no node")
    return args


def main(argv: list[str] | None = None) -> int:
    try:
        own, ros_args = split_ros_args(
            "pd_lifecycle_manager", sys.argv[1:] if argv is None else argv
        )
    except UsageError as exc:
        print(exc, file=sys.stderr)
        return 2
    args = parse_args(own)
    stop = threading.Event()
    tearing_down = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    rclpy.init(
        args=["pd_lifecycle_manager", *ros_args], signal_handler_options=SignalHandlerOptions.NO
    )
    node = Node("pd_lifecycle_manager")
    executor = SingleThreadedExecutor()
    executor.add_node(node)

    def interrupted() -> bool:
        return stop.is_set() and not tearing_down.is_set()

    def spin_until(predicate: Callable[[], bool], timeout_s: float) -> bool:
        session.spin_until(executor, lambda: predicate() or interrupted(), timeout_s)
        return bool(predicate())

    def say(line: str) -> None:
        print(f"pd_lifecycle_manager: {line}", flush=True)

    manager = LifecycleManager(
        node,
        spin_until,
        args.nodes,
        say,
        args.heartbeat_timeout,
        args.transition_timeout,
        interrupted=interrupted,
    )
    status = 0
    try:
        missing = manager.wait_for_services(args.service_timeout)
        if missing and not stop.is_set():
            say(f"no lifecycle services of {', '.join(missing)} within {args.service_timeout:g} s")
            status = 1
        elif not stop.is_set():
            if manager.startup():
                say(f"up: {', '.join(args.nodes)} active; watching")
            while not stop.is_set() and rclpy.ok():
                executor.spin_once(timeout_sec=0.1)
                manager.watch()
    except KeyboardInterrupt:
        pass
    finally:
        tearing_down.set()
        say("stopping: deactivate, cleanup, shutdown in reverse order")
        manager.shutdown()
        status = status or int(manager.failure is not None)
        executor.remove_node(node)
        node.destroy_node()
        executor.shutdown(timeout_sec=1.0)
        rclpy.try_shutdown()
    return status


if __name__ == "__main__":
    sys.exit(main())
