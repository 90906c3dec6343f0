"""Which node published a message, from its writer's gid (for the simulator's `command_source`).

rclpy hands a two-argument callback the writer's gid (MessageInfo `publisher_gid`), and the ROS
graph lists each publisher of a topic with its node name and the same gid
(`Node.get_publishers_info_by_topic`). The graph is asked again only for a gid not seen yet: a
message can arrive before discovery has reported its writer, so an unknown gid is looked up on
every message until it resolves (and is "" meanwhile).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from typing import Any


class PublisherNames:
    """gid -> node name of the publishers of one topic, cached."""

    def __init__(self, publishers: Callable[[], Iterable[Any]]) -> None:
        """`publishers()`: the topic's endpoints (`node_name`, `endpoint_gid`), e.g.
        `lambda: node.get_publishers_info_by_topic(topic)`."""
        self._publishers = publishers
        self._names: dict[bytes, str] = {}
        self.lookups = 0

    def name_of(self, info: Mapping[str, Any]) -> str:
        """Node name of the message's publisher; "" if the graph does not list it (yet)."""
        gid = info.get("publisher_gid")
        if not gid:
            return ""
        key = bytes(gid["data"])
        if key not in self._names:
            self.lookups += 1
            for e in self._publishers():
                self._names[bytes(bytearray(e.endpoint_gid))] = e.node_name
        return self._names.get(key, "")
