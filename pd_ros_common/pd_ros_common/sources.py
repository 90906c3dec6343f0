"""Which node published a message, from its writer's gid (for the simulator's `command_source`).

rclpy hands a two-argument callback the writer's gid (MessageInfo `publisher_gid`), and the ROS
graph lists each publisher of a topic with its node name and the same gid
(`Node.get_publishers_info_by_topic`). The graph is asked again only for a gid not resolved yet:
a message can arrive before discovery has reported its writer, or with the writer listed but its
node not yet (Fast DDS names it `_NODE_NAME_UNKNOWN_` until the node's discovery info arrives),
so such a gid is looked up on every message until it resolves (and is "" meanwhile; never
cached, or a legitimate node seen early would be refused for good).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from typing import Any

UNRESOLVED = ("", "_NODE_NAME_UNKNOWN_")  # what the graph says before it knows the node


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
                if e.node_name not in UNRESOLVED:
                    self._names[bytes(bytearray(e.endpoint_gid))] = e.node_name
        return self._names.get(key, "")
