"""lander/thrust_cmd as pd_sim_node receives it, and what it says about the commands.

Contract: every message becomes a `pd_core.commands.Command` handed to the node (`on_command`),
with the name of the node that published it when `named_sources` (the simulator's
`command_source` is set; "" while the ROS graph cannot name it yet). Commands that never arrive
are counted in `lost` and logged: a gap in a publisher's sequence numbers (its queue overflowed)
and DDS message-lost events. A change in the matched endpoints (a policy or monitor joins or
leaves) is logged. `rejected` and `foreign` log the node's verdicts: rejected commands one by one
up to `log_rejections`, then every 100th; the first command of each other lander as an error.

Mechanism: `pd_ros_common.gaps.SequenceGaps` and `pd_ros_common.sources.PublisherNames` over the
two-argument subscription callback (rclpy's MessageInfo); a 0.1 s timer compares the matched
counts. The subscription and timer are owned by the node (cleanup destroys them).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.publisher import Publisher

from pd_core.commands import Command
from pd_interfaces.msg import ThrustCommand
from pd_ros_common import names, qos
from pd_ros_common.convert import command_from_msg
from pd_ros_common.gaps import SequenceGaps
from pd_ros_common.lifecycle import ManagedNode
from pd_ros_common.sources import PublisherNames

LINKS_PERIOD_S = 0.1  # how often the matched endpoints are compared


class CommandInput:
    """The lander/thrust_cmd subscription of `node`; `state_pub` is its lander/state writer (whose
    readers the links line counts)."""

    def __init__(
        self,
        node: ManagedNode,
        on_command: Callable[[Command], None],
        state_pub: Publisher,
        named_sources: bool,
        log_rejections: int,
    ) -> None:
        self._node = node
        self._on_command = on_command
        self._state_pub = state_pub
        self._named_sources = named_sources
        self._log_rejections = log_rejections
        self.lost = 0  # never arrived: sequence gaps plus DDS message-lost events
        self._gaps = SequenceGaps()
        self._sources = PublisherNames(
            lambda: node.get_publishers_info_by_topic(self.sub.topic_name)
        )
        self.sub = node.own(
            node.create_subscription(
                ThrustCommand,
                names.COMMAND_TOPIC,
                self._on_msg,
                qos.LOOP_SUB_QOS,
                event_callbacks=SubscriptionEventCallbacks(message_lost=self._on_lost),
            )
        )
        self._links = (-1, -1)
        node.own(node.create_timer(LINKS_PERIOD_S, self._log_links))

    def rejected(self, err: tuple[str, str], n: int) -> None:
        """Log a rejected command (`err`: kind, reason), the `n`-th so far, unless throttled."""
        if n <= self._log_rejections or n % 100 == 0:
            self._node.get_logger().warning(
                f"command rejected ({err[0]}): {err[1]} [{n} rejected so far]"
            )

    def foreign(self, other: str, own: str) -> None:
        """Log the first command for lander `other` heard by lander `own`: a set-up error."""
        self._node.get_logger().error(
            f"commands for lander {other!r} arrive on {self.sub.topic_name}; this is lander "
            f"{own!r}: a second stack shares these names (give each its own namespace, -r "
            "__ns:=/vehicle2). Its commands are counted as foreign, never flown"
        )

    def _on_msg(self, msg: ThrustCommand, info: Any) -> None:
        missing, first, last = self._gaps.update(info)
        if missing:  # a sender's queue overflowed: those commands never reached us
            self._count_lost(missing, f"of one publisher never arrived (sequence {first}..{last})")
        source = self._sources.name_of(info) if self._named_sources else ""
        self._on_command(command_from_msg(msg, source))

    def _on_lost(self, info: Any) -> None:
        """Commands DDS reports lost before they reached us: count and log."""
        self._count_lost(int(info.total_count_change), "reported lost by DDS")

    def _count_lost(self, n: int, how: str) -> None:
        self.lost += n
        self._node.get_logger().warning(f"{n} command(s) {how} [{self.lost} lost so far]")

    def _log_links(self) -> None:
        """Log when a policy (or monitor) joins or leaves: the matched DDS endpoints change."""
        links = (self._state_pub.get_subscription_count(), self.sub.get_publisher_count())
        if links != self._links:
            self._links = links
            self._node.get_logger().info(
                f"links: {links[0]} subscriber(s) of {self._state_pub.topic_name}, "
                f"{links[1]} publisher(s) of {self.sub.topic_name}"
            )
