"""The managed-node state machine's arithmetic, without ROS: which transitions lead from a state
to a goal, in which order a stack goes up and down, and when a node counts as gone.

The ids are those of `lifecycle_msgs` (State.PRIMARY_STATE_*, Transition.TRANSITION_*), the
machine the ROS 2 design "Managed nodes" (design.ros2.org/articles/node_lifecycle.html) and
rcl_lifecycle define. `pd_ros_common.lifecycle` (the nodes' side) and `pd_bringup`'s lifecycle
manager use this module; it is unit-tested without a ROS context.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

# primary states (lifecycle_msgs/msg/State)
UNKNOWN, UNCONFIGURED, INACTIVE, ACTIVE, FINALIZED = 0, 1, 2, 3, 4
STATE_LABELS = {
    UNKNOWN: "unknown",
    UNCONFIGURED: "unconfigured",
    INACTIVE: "inactive",
    ACTIVE: "active",
    FINALIZED: "finalized",
}
# transitions (lifecycle_msgs/msg/Transition)
CONFIGURE, CLEANUP, ACTIVATE, DEACTIVATE = 1, 2, 3, 4
UNCONFIGURED_SHUTDOWN, INACTIVE_SHUTDOWN, ACTIVE_SHUTDOWN = 5, 6, 7
TRANSITION_LABELS = {
    CONFIGURE: "configure",
    CLEANUP: "cleanup",
    ACTIVATE: "activate",
    DEACTIVATE: "deactivate",
    UNCONFIGURED_SHUTDOWN: "shutdown",
    INACTIVE_SHUTDOWN: "shutdown",
    ACTIVE_SHUTDOWN: "shutdown",
}
# (start, transition) -> goal of every valid transition from a primary state
EDGES: dict[tuple[int, int], int] = {
    (UNCONFIGURED, CONFIGURE): INACTIVE,
    (INACTIVE, CLEANUP): UNCONFIGURED,
    (INACTIVE, ACTIVATE): ACTIVE,
    (ACTIVE, DEACTIVATE): INACTIVE,
    (UNCONFIGURED, UNCONFIGURED_SHUTDOWN): FINALIZED,
    (INACTIVE, INACTIVE_SHUTDOWN): FINALIZED,
    (ACTIVE, ACTIVE_SHUTDOWN): FINALIZED,
}
SHUTDOWN_FROM = {
    UNCONFIGURED: UNCONFIGURED_SHUTDOWN,
    INACTIVE: INACTIVE_SHUTDOWN,
    ACTIVE: ACTIVE_SHUTDOWN,
}


def state_label(state: int) -> str:
    return STATE_LABELS.get(state, f"transitional state {state}")


def transition_label(transition: int) -> str:
    return TRANSITION_LABELS.get(transition, f"transition {transition}")


def valid(state: int, transition: int) -> bool:
    """True if `transition` may start from primary state `state`."""
    return (state, transition) in EDGES


def valid_from(state: int) -> list[str]:
    """Labels of the transitions that may start from `state` (for a refusal's message)."""
    return [transition_label(t) for (s, t) in EDGES if s == state]


def path(state: int, goal: int) -> list[int]:
    """The transitions that take a node from primary state `state` to `goal`, shortest first
    (the machine has no cycles through FINALIZED): [] when already there. ValueError when no
    path exists (out of FINALIZED, or from a transitional state)."""
    if state == goal:
        return []
    if state not in SHUTDOWN_FROM:
        raise ValueError(f"no transition leads from {state_label(state)} to {state_label(goal)}")
    if goal == FINALIZED:
        return [SHUTDOWN_FROM[state]]
    order = [UNCONFIGURED, INACTIVE, ACTIVE]
    if goal not in order:
        raise ValueError(f"{state_label(goal)} is not a goal state")
    up = {UNCONFIGURED: CONFIGURE, INACTIVE: ACTIVATE}
    down = {ACTIVE: DEACTIVATE, INACTIVE: CLEANUP}
    steps: list[int] = []
    s = state
    while s != goal:
        t = up[s] if order.index(goal) > order.index(s) else down[s]
        steps.append(t)
        s = EDGES[(s, t)]
    return steps


def bringup(nodes: Sequence[str]) -> list[tuple[str, int]]:
    """(node, transition) in order: configure every node in list order, then activate them in
    the same order (as nav2's lifecycle_manager does)."""
    return [(n, CONFIGURE) for n in nodes] + [(n, ACTIVATE) for n in nodes]


def teardown(nodes: Sequence[str]) -> list[str]:
    """The order a stack goes down in: the reverse of `nodes`."""
    return list(reversed(nodes))


@dataclass
class Heartbeats:
    """When each watched node was last heard (its /diagnostics), and which are overdue.

    A node is watched from `expect(name, now)` on (a transition just completed, so a slow
    configure that held its executor does not count); `beat(name, now)` records a heartbeat;
    `overdue(now)` lists (name, seconds since the last) of the watched nodes heard from longer
    ago than `timeout_s`."""

    timeout_s: float
    last: dict[str, float] = field(default_factory=dict)

    def expect(self, name: str, now: float) -> None:
        self.last[name] = now

    def forget(self, name: str) -> None:
        self.last.pop(name, None)

    def beat(self, name: str, now: float) -> None:
        if name in self.last:
            self.last[name] = max(self.last[name], now)

    def overdue(self, now: float) -> list[tuple[str, float]]:
        return [(n, now - t) for n, t in self.last.items() if now - t > self.timeout_s]


def failure_line(failed: str, why: str, deactivated: Iterable[str]) -> str:
    """The one line the manager says when a node fails: who, why, and what it took down."""
    others = list(deactivated)
    taken = f"deactivated {', '.join(others)}" if others else "no other node was active"
    return f"{failed} failed ({why}); {taken}"
