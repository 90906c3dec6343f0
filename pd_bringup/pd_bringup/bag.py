"""rosbag2 (MCAP) helpers shared by pd_record, pd_replay, pd_demo and the tests.

Bags hold the CDR bytes exactly as DDS carried them (raw subscriptions), so `ros2 bag play` /
`ros2 bag info` on a full ROS 2 install read them. Each topic's offered QoS profiles are stored
the way rosbag2 stores them (`offered_qos_profiles`, in metadata.yaml and in the MCAP channel's
metadata), and `pd_replay` offers the same.

A bag whose recorder was killed has no metadata.yaml and its MCAP file no summary or footer:
`read_bag` then scans the file record by record (the recorder closes a chunk every half second)
and recovers every complete chunk, with the topics, types and QoS of its channel records.
"""

from __future__ import annotations

import importlib
import io
import os
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.rosbag2.storage_mcap import decompress, get_qos
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from pd_ros_common.qos import HISTORY_DEPTH

INTERFACES = "pd_interfaces"
MCAP_MAGIC = b"\x89MCAP0\r\n"
_DEFAULT_TIME = QosTime(0, 0)  # 0 = the RMW default (infinite)


class BagError(RuntimeError):
    """A bag that cannot be read at all (one line: the path and what is wrong)."""


# ---------------------------------------------------------------------------------- types
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


# ---------------------------------------------------------------------------------- QoS
def bag_qos(profile: QoSProfile) -> Qos:
    """rosbags (rosbag2 metadata) form of an rclpy QoS profile; durations left at default."""
    return Qos(
        QosHistory(int(profile.history)),
        int(profile.depth),
        QosReliability(int(profile.reliability)),
        QosDurability(int(profile.durability)),
        _DEFAULT_TIME,
        _DEFAULT_TIME,
        QosLiveliness(int(profile.liveliness)),
        _DEFAULT_TIME,
        False,
    )


def replay_qos(offered: list[Qos]) -> QoSProfile:
    """What a replay offers, as rosbag2 does: RELIABLE (TRANSIENT_LOCAL) only if every
    recorded publisher offered it; depth the largest recorded, else HISTORY_DEPTH."""
    reliable = bool(offered) and all(q.reliability == QosReliability.RELIABLE for q in offered)
    latched = bool(offered) and all(q.durability == QosDurability.TRANSIENT_LOCAL for q in offered)
    depths = [q.depth for q in offered if q.history == QosHistory.KEEP_LAST and q.depth > 0]
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=max(depths) if depths else HISTORY_DEPTH,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )


# ---------------------------------------------------------------------------------- writing
def open_writer(path: str | Path) -> Writer:
    """A rosbag2 v9 MCAP writer at `path` (a folder that must not exist yet), opened."""
    writer = Writer(Path(path), version=Writer.VERSION_LATEST, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    return writer


def flush_writer(writer: Writer) -> None:
    """Close the MCAP chunk being filled and push it to the file (what a SIGKILL keeps)."""
    storage = writer.storage
    if storage is not None and storage.chunk.bio.tell():
        storage.close_chunk()
    if storage is not None:
        storage.bio.flush()


# ---------------------------------------------------------------------------------- reading
@dataclass
class Bag:
    """A bag's topics {topic: (msgtype, offered QoS)} and messages (topic, stamp ns, raw CDR)."""

    topics: dict[str, tuple[str, list[Qos]]] = field(default_factory=dict)
    messages: list[tuple[str, int, bytes]] = field(default_factory=list)
    recovered: bool = False  # read by scanning a bag without metadata or footer

    @property
    def duration_ns(self) -> int:
        stamps = [m[1] for m in self.messages]
        return max(stamps) - min(stamps) if stamps else 0


def read_bag(path: str | Path, topics: list[str] | None = None) -> Bag:
    """Every message of a bag in time order; a bag without metadata/footer is scanned."""
    path = Path(path)
    if not path.is_dir():
        raise BagError(f"{path}: no such bag folder")
    try:
        with Reader(path) as reader:
            bag = Bag(
                {c.topic: (c.msgtype, list(c.ext.offered_qos_profiles)) for c in reader.connections}
            )
            conns = [c for c in reader.connections if topics is None or c.topic in topics]
            for conn, stamp, raw in reader.messages(connections=conns):
                bag.messages.append((conn.topic, stamp, bytes(raw)))
        return bag
    except Exception:  # no metadata.yaml, no footer, ...: recover what the file holds
        files = sorted(path.glob("*.mcap"))
        if not files:
            raise BagError(f"{path}: no metadata.yaml and no .mcap file") from None
        bag = Bag(recovered=True)
        for f in files:
            _scan_mcap(f, bag, topics)
        bag.messages.sort(key=lambda m: m[1])
        return bag


def read_messages(path: str | Path, topics: list[str] | None = None) -> Iterator[tuple]:
    """(topic, msgtype, timestamp ns, raw CDR bytes) of a bag, in time order."""
    bag = read_bag(path, topics)
    for topic, stamp, raw in bag.messages:
        yield topic, bag.topics[topic][0], stamp, raw


def deserialize_all(path: str | Path, topics: list[str] | None = None) -> dict[str, list[Any]]:
    """Every message of a bag decoded by rosbags (not rclpy): {topic: [message, ...]}."""
    store = typestore()
    out: dict[str, list[Any]] = {}
    for topic, msgtype, _, raw in read_messages(path, topics):
        out.setdefault(topic, []).append(store.deserialize_cdr(raw, msgtype))
    return out


def _string(buf: memoryview, at: int) -> tuple[str, int]:
    (n,) = struct.unpack_from("<I", buf, at)
    return bytes(buf[at + 4 : at + 4 + n]).decode(), at + 4 + n


def _records(f: BinaryIO, end: int) -> Iterator[tuple[int, memoryview]]:
    """(opcode, content) of each complete record before offset `end`; stops at the first
    truncated (or garbled: longer than what is left) one."""
    while True:
        head = f.read(9)
        if len(head) < 9:
            return
        op, length = struct.unpack("<BQ", head)
        if length > end - f.tell():
            return
        content = f.read(length)
        if len(content) < length:
            return
        yield op, memoryview(content)


def _scan_mcap(path: Path, bag: Bag, topics: list[str] | None) -> None:
    """Add the channels and messages of every complete record of an MCAP file to `bag`."""
    with open(path, "rb") as f:
        if f.read(8) != MCAP_MAGIC:
            raise BagError(f"{path}: not an MCAP file")
        _scan_records(_records(f, path.stat().st_size), bag, topics, {}, {})


def _scan_records(
    records: Iterator[tuple[int, memoryview]],
    bag: Bag,
    topics: list[str] | None,
    schemas: dict[int, str],
    channels: dict[int, str],
) -> None:
    for op, rec in records:
        try:
            _scan_record(op, rec, bag, topics, schemas, channels)
        except (struct.error, ValueError, UnicodeDecodeError, IndexError):
            return  # a garbled record: keep what came before it


def _scan_record(
    op: int,
    rec: memoryview,
    bag: Bag,
    topics: list[str] | None,
    schemas: dict[int, str],
    channels: dict[int, str],
) -> None:
    """One record: schemas and channels are remembered, messages added to `bag`."""
    if op == 0x03:  # schema: id, name, encoding, data
        (sid,) = struct.unpack_from("<H", rec, 0)
        schemas[sid] = _string(rec, 2)[0]
    elif op == 0x04:  # channel: id, schema id, topic, encoding, metadata
        cid, sid = struct.unpack_from("<HH", rec, 0)
        topic, at = _string(rec, 4)
        _, at = _string(rec, at)
        (n,) = struct.unpack_from("<I", rec, at)
        channels[cid] = topic
        offered = get_qos(bytes(rec[at + 4 : at + 4 + n]))
        bag.topics.setdefault(topic, (schemas.get(sid, ""), offered))
    elif op == 0x05:  # message: channel, sequence, log time, publish time, data
        cid, _, stamp = struct.unpack_from("<HIQ", rec, 0)
        topic = channels.get(cid)
        if topic is not None and (topics is None or topic in topics):
            bag.messages.append((topic, stamp, bytes(rec[22:])))
    elif op == 0x06:  # chunk: start, end, size, crc, compression, records
        _, _, size, crc = struct.unpack_from("<QQQI", rec, 0)
        compression, at = _string(rec, 28)
        (n,) = struct.unpack_from("<Q", rec, at)
        data = decompress(bytes(rec[at + 8 : at + 8 + n]), compression, size, crc)
        _scan_records(_records(io.BytesIO(data), len(data)), bag, topics, schemas, channels)
