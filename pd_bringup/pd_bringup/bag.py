"""rosbag2 (MCAP) helpers shared by pd_record, pd_replay, pd_demo and the tests.

Bags hold the CDR bytes exactly as DDS carried them (rclpy `serialize_message`, or raw
subscriptions), so `ros2 bag play` / `ros2 bag info` on a full ROS 2 install read them. The
`rosbags` typestore knows the ROS 2 Kilted standard types; pd_interfaces types are registered
from their installed .msg files.
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

INTERFACES = "pd_interfaces"

# What the stack's publishers offer (RELIABLE, KEEP_LAST 10, VOLATILE; durations 0 = default),
# stored with each connection so `ros2 bag play` offers the same.
_DEFAULT_TIME = QosTime(0, 0)
LOOP_QOS = Qos(
    QosHistory.KEEP_LAST,
    10,
    QosReliability.RELIABLE,
    QosDurability.VOLATILE,
    _DEFAULT_TIME,
    _DEFAULT_TIME,
    QosLiveliness.AUTOMATIC,
    _DEFAULT_TIME,
    False,
)


def interface_dir(package: str = INTERFACES) -> Path:
    """share/<package> of the installed interface package (AMENT_PREFIX_PATH, else next to the
    importable Python package)."""
    for prefix in filter(None, os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)):
        share = Path(prefix) / "share" / package
        if (share / "msg").is_dir():
            return share
    mod = importlib.import_module(package)
    # <prefix>/lib/python3.X/site-packages/<package>/__init__.py -> <prefix>/share/<package>
    share = Path(mod.__file__).resolve().parents[4] / "share" / package
    if (share / "msg").is_dir():
        return share
    raise FileNotFoundError(f"no share/{package}/msg found (source env.sh first)")


def typestore() -> Any:
    """rosbags typestore: ROS 2 Kilted types plus every pd_interfaces message."""
    store = get_typestore(Stores.ROS2_KILTED)
    types: dict[str, Any] = {}
    for f in sorted((interface_dir() / "msg").glob("*.msg")):
        types.update(get_types_from_msg(f.read_text(), f"{INTERFACES}/msg/{f.stem}"))
    store.register(types)
    return store


def message_class(msgtype: str) -> type:
    """rclpy message class of 'pkg/msg/Name'."""
    pkg, kind, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{pkg}.{kind}"), name)


def type_name(msg_class: type) -> str:
    """'pkg/msg/Name' of an rclpy message class."""
    pkg = msg_class.__module__.split(".")[0]
    return f"{pkg}/msg/{msg_class.__name__}"


def open_writer(path: str | Path) -> Writer:
    """A rosbag2 v9 MCAP writer at `path` (a folder that must not exist yet), opened."""
    writer = Writer(Path(path), version=Writer.VERSION_LATEST, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    return writer


def read_messages(path: str | Path, topics: list[str] | None = None) -> Iterator[tuple]:
    """(topic, msgtype, timestamp ns, raw CDR bytes) of a bag, in time order."""
    with Reader(Path(path)) as reader:
        conns = [c for c in reader.connections if topics is None or c.topic in topics]
        for conn, stamp, raw in reader.messages(connections=conns):
            yield conn.topic, conn.msgtype, stamp, raw


def deserialize_all(path: str | Path, topics: list[str] | None = None) -> dict[str, list[Any]]:
    """Every message of a bag decoded by rosbags (not rclpy): {topic: [message, ...]}."""
    store = typestore()
    out: dict[str, list[Any]] = {}
    for topic, msgtype, _, raw in read_messages(path, topics):
        out.setdefault(topic, []).append(store.deserialize_cdr(raw, msgtype))
    return out
