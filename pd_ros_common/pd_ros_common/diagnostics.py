"""/diagnostics of the stack's nodes and tools (`diagnostic_msgs/DiagnosticArray`, 1 Hz).

Every node (and `pd_record`) publishes, once per `PERIOD_S`, one DiagnosticStatus on the absolute
topic `/diagnostics` (where `rqt_robot_monitor`, Foxglove's diagnostics panel and
`ros2 topic echo /diagnostics` look for it): name `<node path>: <task>` (e.g.
`pd_sim_node: simulator`, `vehicle1/pd_sim_node: simulator` in a namespace), hardware_id the
lander id where there is one, a level, a one-line message and key/values. A node only says what
its numbers are and which rules hold (`Report`); this module builds the message and publishes it.

Levels, from simple rules over the last period (the README lists them):

- pd_sim_node: ERROR when commands for another lander id arrived (a second stack on the same
  names); WARN when steps were flown without a fresh command (missed), commands were rejected or
  lost, or (real time, flying the whole period) the achieved step rate was under 90 % of rate_hz;
  else OK.
- pd_policy_node: ERROR when states of more than one lander id arrived (a second simulator on the
  same names); WARN when states were invalid, missing (step gaps) or lost, or the decision time
  p99 exceeded `SLOW_DECISION_S` (half a 0.2 s step); else OK.
- pd_ocp_node: WARN when a request was answered busy or failed; else OK.
- pd_record: ERROR when a message never reached the recorder (a gap or a DDS loss) or was not
  written, since the recording began; else OK. A path superseded on a latest-value topic
  (lander/path, ocp/plan) is reported, not an error. WARN when a publisher that appeared while
  recording sent messages before it matched the recorder (not in the bag; counted).

pd_sim_node and pd_policy_node also report `readers <topic>` for each topic they publish: the
subscriptions their DDS writer has matched (`Publisher.get_subscription_count`). A reliable,
volatile writer delivers only to the readers it has matched, so a tool that must not miss the
first messages (pd_demo's recorder) waits for these counts, not for the ROS graph.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node
from rclpy.publisher import Publisher

from pd_ros_common import names, qos

# DiagnosticStatus levels as ints (the message holds them as one byte)
OK, WARN, ERROR, STALE = 0, 1, 2, 3
LEVEL_NAMES = {OK: "OK", WARN: "WARN", ERROR: "ERROR", STALE: "STALE"}
PERIOD_S = 1.0
SLOW_DECISION_S = 0.1  # policy: WARN when the decision time p99 of a period is above this
RATE_SHORTFALL = 0.9  # simulator (real time): WARN when the achieved rate is under this share


@dataclass
class Report:
    """What a node says about itself for one period: its key/values and the rules that hold.

    `rule(level, holds, reason)` adds a rule; the status level is the worst level of the rules
    that hold, and the message their reasons (or `ok_message` when none holds)."""

    values: dict[str, Any] = field(default_factory=dict)
    ok_message: str = "ok"
    _fired: list[tuple[int, str]] = field(default_factory=list)

    def rule(self, level: int, holds: bool, reason: str) -> Report:
        if holds:
            self._fired.append((level, reason))
        return self

    @property
    def level(self) -> int:
        return max((lv for lv, _ in self._fired), default=OK)

    @property
    def message(self) -> str:
        if not self._fired:
            return self.ok_message
        ordered = sorted(self._fired, key=lambda f: -f[0])
        return "; ".join(reason for _, reason in ordered)


def text(value: Any) -> str:
    """A key/value's value as text: floats to 6 significant digits, booleans lower case."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return "nan" if math.isnan(value) else f"{value:.6g}"
    if isinstance(value, (list, tuple, set, frozenset)):
        return ", ".join(text(v) for v in value)
    return str(value)


def status(
    name: str, report: Report, hardware_id: str = "", level: int | None = None
) -> DiagnosticStatus:
    """The DiagnosticStatus of `report` (its key/values in their order)."""
    return DiagnosticStatus(
        level=bytes([report.level if level is None else level]),
        name=name,
        message=report.message,
        hardware_id=hardware_id,
        values=[KeyValue(key=str(k), value=text(v)) for k, v in report.values.items()],
    )


def values_of(s: DiagnosticStatus) -> dict[str, str]:
    """{key: value} of a DiagnosticStatus (for tests and tools)."""
    return {kv.key: kv.value for kv in s.values}


def level_of(s: DiagnosticStatus) -> int:
    """The level of a DiagnosticStatus as an int (rclpy gives a bytes of length 1)."""
    lv = s.level
    return lv[0] if isinstance(lv, (bytes, bytearray)) else int(lv)


class Since:
    """Change of running totals since the previous call: `since(missed=10, ...)` gives
    {"missed": 10 - the last value, ...} (the totals themselves on the first call)."""

    def __init__(self) -> None:
        self._last: dict[str, float] = {}

    def __call__(self, **totals: float) -> dict[str, float]:
        out = {k: v - self._last.get(k, 0) for k, v in totals.items()}
        self._last = dict(totals)
        return out


def readers(*publishers: Publisher) -> dict[str, int]:
    """{"readers <topic>": its matched subscriptions} of each publisher (DDS, not the graph)."""
    return {f"readers {p.topic_name}": int(p.get_subscription_count()) for p in publishers}


def status_name(node: Node, task: str) -> str:
    """`<namespace/node>: <task>`, as diagnostic_updater names a node's task."""
    return f"{node.get_fully_qualified_name().lstrip('/')}: {task}"


class Diagnostics:
    """Publishes `report()` of `node` on /diagnostics every `period_s` (a timer of the node).

    `report` runs in the node's executor, like any callback: take the node's lock if its numbers
    are changed from another thread. `hardware_id` may be a callable (an id known later)."""

    def __init__(
        self,
        node: Node,
        task: str,
        report: Callable[[], Report],
        hardware_id: str | Callable[[], str] = "",
        period_s: float = PERIOD_S,
    ) -> None:
        self._node = node
        self._report = report
        self._hardware_id = hardware_id
        self.name = status_name(node, task)
        self.published = 0
        self._pub = node.create_publisher(
            DiagnosticArray, names.DIAGNOSTICS_TOPIC, qos.DIAGNOSTICS_QOS
        )
        self._timer = node.create_timer(period_s, self.publish)

    def publish(self) -> DiagnosticArray:
        hw = self._hardware_id() if callable(self._hardware_id) else self._hardware_id
        msg = array(self._node, [status(self.name, self._report(), hw)])
        self._pub.publish(msg)
        self.published += 1
        return msg


def array(node: Node, statuses: Iterable[DiagnosticStatus]) -> DiagnosticArray:
    """A DiagnosticArray stamped with the node's clock now."""
    msg = DiagnosticArray(status=list(statuses))
    msg.header.stamp = node.get_clock().now().to_msg()
    return msg


def counts_share(counts: Mapping[str, int], base: str) -> dict[str, float]:
    """{source: its share of all steps} for every source but `base` (the runtime layer's share
    of changed actions per rule, from `Runtime.counts`); 0 when nothing was decided yet."""
    total = sum(counts.values())
    return {k: (v / total if total else 0.0) for k, v in counts.items() if k != base}


class Listener:
    """Subscribes `node` to /diagnostics: the latest DiagnosticStatus of each name and every level
    seen (for tools and tests that watch the stack)."""

    def __init__(self, node: Node) -> None:
        self.latest: dict[str, DiagnosticStatus] = {}
        self.levels: dict[str, set[int]] = {}
        node.create_subscription(
            DiagnosticArray, names.DIAGNOSTICS_TOPIC, self._on, qos.DIAGNOSTICS_QOS
        )

    def _on(self, msg: DiagnosticArray) -> None:
        for s in msg.status:
            self.latest[s.name] = s
            self.levels.setdefault(s.name, set()).add(level_of(s))

    def values(self, name: str) -> dict[str, str]:
        """{key: value} of the latest status of `name` ({} before the first)."""
        return values_of(self.latest[name]) if name in self.latest else {}

    def highest(self, key: str) -> int:
        """The highest integer value of `key` in any name's latest status (-1 before one)."""
        found = [int(v[key]) for v in map(values_of, self.latest.values()) if key in v]
        return max(found, default=-1)

    def readers(self, topic: str) -> int:
        """The matched readers the writer of the absolute `topic` reported last (-1 before it)."""
        return self.highest(f"readers {topic}")
