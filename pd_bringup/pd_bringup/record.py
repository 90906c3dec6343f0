"""pd_record: record topics to a rosbag2 bag (MCAP storage) with the `rosbags` library.

    pd_record                                  # the stack's topics (names.RECORD_TOPICS)
    pd_record -o bags/run1 /lander/state /lander/thrust_cmd
    pd_record --duration 30 /lander/state
    pd_record --ros-args -r __ns:=/vehicle1     # the stack of namespace /vehicle1

Messages are taken as raw CDR (raw subscriptions), so the bag holds exactly the bytes DDS carried,
stamped with their receive time (as `ros2 bag record` does). The subscription callbacks only
queue the bytes; a writer thread writes them and closes an MCAP chunk every `--flush` seconds, so
a SIGKILL loses at most that much and the bag still opens (`pd_bringup.bag.read_bag`). Each
publisher's sequence numbers are followed: a message that never reached the recorder (a gap) is
counted and logged, and the exit status is then 1. On the latest-value topics (lander/path,
ocp/plan: depth 1, `qos.keeps_latest_only`) a newer path may replace one not yet delivered, by
design; those are counted as superseded, not lost. Ctrl-C or SIGTERM (at any moment, again
during the stop, as `ros2 launch` sends SIGINT then SIGTERM) stops recording within a second:
what has arrived is written, the bag is closed and its metadata.yaml written, exit status 0. Each
topic's offered QoS (from the ROS graph when its first message arrives; for a topic never heard,
when the stop begins, while the node still exists) is stored in the bag. Relative topic names
resolve in the recorder's namespace; topics of unknown type are looked up in the ROS graph (a
stop during that wait records the topics whose type is known). ROS arguments (`--ros-args ...`)
may come anywhere on the command line.

A publisher that appears while it records (a simulator restarted after a crash) sends its first
messages before DDS has matched it with the recorder, and a reliable, volatile writer never
sends those to a reader it matched later: they cannot be recorded. Such a publisher (first seen
in the graph more than NEW_PUBLISHER_AFTER_S after the start) is known by its sequence numbers,
which start at 1: the messages before its first one are counted, logged, in the closing line
("missed before a new publisher matched") and in metadata.yaml's custom_data
(`pd_record.missed_before_match`, beside `pd_record.lost`); /diagnostics is then at WARN.

By default it records the lander/* topics, the viewer topics (lander/odom, lander/path,
ocp/plan), /diagnostics and the managed nodes' `<node>/transition_event`
(lifecycle_msgs/TransitionEvent), not /clock (`ros2 bag play --clock` makes one). It publishes
its own /diagnostics at 1 Hz: messages per topic, gaps (never arrived), DDS losses, messages
queued and not written; ERROR once anything was lost (pd_ros_common.diagnostics).
"""

from __future__ import annotations

import argparse
import queue
import signal
import sys
import threading
import time
from collections.abc import Callable
from datetime import datetime
from pathlib import Path
from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from lifecycle_msgs.msg import TransitionEvent
from nav_msgs.msg import Odometry
from nav_msgs.msg import Path as PathMsg
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from rosbags.interfaces import Qos
from rosgraph_msgs.msg import Clock

from pd_bringup.bag import bag_qos, flush_writer, message_class, open_writer, type_name, typestore
from pd_interfaces.msg import EpisodeResult, GuidanceStatus, LanderState, ThrustCommand
from pd_ros_common import diagnostics, names, qos
from pd_ros_common.cli import UsageError, split_ros_args
from pd_ros_common.gaps import SequenceGaps

KNOWN_TYPES: dict[str, type] = {
    names.STATE_TOPIC: LanderState,
    names.COMMAND_TOPIC: ThrustCommand,
    names.EPISODE_TOPIC: EpisodeResult,
    names.GUIDANCE_TOPIC: GuidanceStatus,
    names.ODOM_TOPIC: Odometry,
    names.PATH_TOPIC: PathMsg,
    names.PLAN_TOPIC: PathMsg,
    names.DIAGNOSTICS_TOPIC: DiagnosticArray,
    names.CLOCK_TOPIC: Clock,
    **{t: TransitionEvent for t in names.TRANSITION_TOPICS},
}
KNOWN_QOS = {  # fallback when no publisher is seen
    names.EPISODE_TOPIC: qos.EPISODE_QOS,
    names.PATH_TOPIC: qos.PATH_QOS,
    names.PLAN_TOPIC: qos.PATH_QOS,
    names.DIAGNOSTICS_TOPIC: qos.DIAGNOSTICS_QOS,
    names.CLOCK_TOPIC: qos.CLOCK_QOS,
}
# A publisher first seen this long after the recording began appeared while it recorded (a
# restarted node): what it sent before it matched the recorder is counted, not in the bag.
NEW_PUBLISHER_AFTER_S = 3.0
STOP_DRAIN_S = 0.7  # after a stop request, write what is queued for at most this long
TAKE_S = 0.25  # ... after taking, for this long, what DDS had delivered already


class Recorder(Node):
    """Raw subscriptions that only queue (topic index, receive time, bytes, message info)."""

    def __init__(
        self,
        topics: list[str],
        sink: queue.SimpleQueue,
        discovery_s: float,
        stop: threading.Event | None = None,
    ) -> None:
        super().__init__("pd_record")
        self._stop = stop or threading.Event()
        self._qos_lock = threading.Lock()
        self._frozen_qos: dict[str, list[Qos]] | None = None
        known = {self.resolve_topic_name(t): cls for t, cls in KNOWN_TYPES.items()}
        self.known_qos = {self.resolve_topic_name(t): p for t, p in KNOWN_QOS.items()}
        wanted = list(dict.fromkeys(self.resolve_topic_name(t) for t in topics))
        self.types = self._resolve_types(wanted, known, discovery_s)
        self.topics = [t for t in wanted if t in self.types]
        self.latest_only = [  # a gap on these is a superseded message, not a loss
            t in self.known_qos and qos.keeps_latest_only(self.known_qos[t]) for t in self.topics
        ]
        self.lost_events = 0
        self.subscriptions_by_topic = {}
        for i, topic in enumerate(self.topics):
            self.subscriptions_by_topic[topic] = self.create_subscription(
                self.types[topic],
                topic,
                self._queuer(sink, i),
                qos.LOOP_SUB_QOS,
                raw=True,
                event_callbacks=SubscriptionEventCallbacks(message_lost=self._on_lost),
            )
        self._t0 = time.monotonic()
        self._present: list[set[bytes]] = [set() for _ in self.topics]
        self._publishers_timer = None
        self._watch_publishers()
        self._publishers_timer = self.create_timer(0.2, self._watch_publishers)

    def _watch_publishers(self) -> None:
        """The publishers of each topic in the first NEW_PUBLISHER_AFTER_S (the graph)."""
        if time.monotonic() - self._t0 > NEW_PUBLISHER_AFTER_S:
            if self._publishers_timer is not None:
                self._publishers_timer.cancel()
                self.get_logger().info(
                    "publishers that appear from now on are new: what they send before they "
                    "match the recorder is counted as missed"
                )
            return
        for i, topic in enumerate(self.topics):
            found = {bytes(e.endpoint_gid) for e in self.get_publishers_info_by_topic(topic)}
            self._present[i] |= found  # set update: the writer thread only reads

    def is_new(self, index: int) -> Callable[[bytes], bool]:
        """Whether a publisher (gid) of topic `index` appeared while recording: first heard
        after NEW_PUBLISHER_AFTER_S and not in the graph before."""

        def new(gid: bytes) -> bool:
            if time.monotonic() - self._t0 <= NEW_PUBLISHER_AFTER_S:
                return False
            return gid not in self._present[index]

        return new

    @staticmethod
    def _queuer(sink: queue.SimpleQueue, index: int) -> Callable[[bytes, Any], None]:
        put = sink.put

        def on_message(raw: bytes, info: Any) -> None:
            put((index, time.time_ns(), raw, info))

        return on_message

    def _on_lost(self, info: Any) -> None:
        self.lost_events = int(info.total_count)

    def _resolve_types(
        self, topics: list[str], known: dict[str, type], timeout_s: float
    ) -> dict[str, type]:
        types = {t: known[t] for t in topics if t in known}
        if len(types) < len(topics):
            unknown = ", ".join(t for t in topics if t not in types)
            self.get_logger().info(f"waiting up to {timeout_s:g} s for the type of {unknown}")
        deadline = time.monotonic() + timeout_s
        while len(types) < len(topics) and time.monotonic() < deadline:
            for name, kinds in self.get_topic_names_and_types():
                if name in topics and name not in types:
                    types[name] = message_class(kinds[0])
            if self._stop.wait(0.1):
                break
        missing = [t for t in topics if t not in types]
        if missing and self._stop.is_set():  # stopped while waiting: record what is known
            self.get_logger().warning(
                f"stopped before the type of {', '.join(missing)} was known: not recorded"
            )
        elif missing:
            raise SystemExit(
                f"pd_record: type of {', '.join(missing)} unknown (no publisher seen within "
                f"{timeout_s:g} s)"
            )
        return types

    def offered_qos(self, topic: str) -> list[Qos]:
        """QoS offered by the topic's publishers now (the stack's defaults if none is seen);
        after `freeze_qos`, what it found then (the node may be gone: never asked again)."""
        with self._qos_lock:
            if self._frozen_qos is not None:
                return self._frozen_qos.get(topic) or self._default_qos(topic)
            found = [bag_qos(i.qos_profile) for i in self.get_publishers_info_by_topic(topic)]
            return found or self._default_qos(topic)

    def _default_qos(self, topic: str) -> list[Qos]:
        return [bag_qos(self.known_qos.get(topic, qos.LOOP_PUB_QOS))]

    def report_on(self, writer: BagWriter) -> None:
        """Publish /diagnostics of `writer` at 1 Hz."""
        self._since = diagnostics.Since()
        self._writer = writer
        self.diagnostics = diagnostics.Diagnostics(self, "recorder", self._report)

    def _report(self) -> diagnostics.Report:
        w = self._writer
        counts, gaps = list(w.counts), list(w.gaps)
        lost = sum(gaps) + self.lost_events + w.unwritten
        d = self._since(messages=sum(counts))
        r = diagnostics.Report(ok_message=f"recording to {w.bag}")
        r.values = {
            "bag": str(w.bag),
            "messages": sum(counts),
            "messages (last period)": int(d["messages"]),
            **{f"messages {t}": n for t, n in zip(self.topics, counts, strict=True)},
            "gaps (never arrived)": sum(gaps),
            **{f"gaps {t}": n for t, n in zip(self.topics, gaps, strict=True) if n},
            "superseded (latest-value topics)": sum(w.superseded),
            "missed before a new publisher matched": sum(w.before_match),
            "lost (DDS events)": self.lost_events,
            "queued": w.sink.qsize(),
            # publishers each subscription has matched (DDS): a tool waits for these before
            # the first message it needs recorded (pd_demo: the nodes' transition events)
            **{
                f"writers {t}": s.get_publisher_count()
                for t, s in self.subscriptions_by_topic.items()
            },
        }
        r.rule(diagnostics.ERROR, lost > 0, f"{lost} message(s) lost since the start")
        early = sum(w.before_match)
        r.rule(
            diagnostics.WARN,
            early > 0,
            f"{early} message(s) sent by new publishers before they matched the recorder",
        )
        return r

    def freeze_qos(self) -> None:
        """Ask the graph one last time for every topic's QoS; call before `destroy_node` (the
        writer still connects topics first heard in the drain, and the never-heard ones)."""
        frozen = {t: self.offered_qos(t) for t in self.topics}
        with self._qos_lock:
            self._frozen_qos = frozen


class BagWriter(threading.Thread):
    """Writes queued messages into the bag, closes a chunk every `flush_s`, follows gaps."""

    def __init__(self, bag: Path, rec: Recorder, sink: queue.SimpleQueue, flush_s: float) -> None:
        super().__init__(name="pd_record-writer", daemon=True)
        self.bag, self.rec, self.sink, self.flush_s = bag, rec, sink, flush_s
        self.writer = open_writer(bag)
        self.store = typestore()
        self.conns: dict[int, Any] = {}
        self.counts = [0] * len(rec.topics)
        self.gaps = [0] * len(rec.topics)
        self.superseded = [0] * len(rec.topics)
        self.unwritten = 0
        self.before_match = [0] * len(rec.topics)  # sent by new publishers before matching
        self._gaps = [SequenceGaps(rec.is_new(i)) for i in range(len(rec.topics))]
        self._stop_at: float | None = None
        self.error: BaseException | None = None

    def stop(self) -> None:
        """Write what is queued (at most STOP_DRAIN_S), then close the bag."""
        self._stop_at = time.monotonic() + STOP_DRAIN_S

    def run(self) -> None:
        try:
            self._loop()
        except BaseException as exc:  # reported by main(); the bag is closed there
            self.error = exc

    def _loop(self) -> None:
        next_flush = time.monotonic() + self.flush_s
        while True:
            try:
                item = self.sink.get(timeout=0.05)
            except queue.Empty:
                item = None
            now = time.monotonic()
            if item is not None:
                if self._stop_at is not None and now > self._stop_at:
                    self.unwritten += 1 + self.sink.qsize()
                    return
                self._write(*item)
            elif self._stop_at is not None:
                return  # stop requested and the queue is empty
            if now >= next_flush:
                flush_writer(self.writer)
                next_flush = now + self.flush_s

    def _write(self, index: int, stamp: int, raw: bytes, info: Any) -> None:
        topic = self.rec.topics[index]
        if index not in self.conns:
            self._connect(index)
            self.rec.get_logger().info(f"first message on {topic}")
        self.writer.write(self.conns[index], stamp, raw)
        self.counts[index] += 1
        missing, first, last = self._gaps[index].update(info)
        early = self._gaps[index].last_before_match
        if early:
            self.before_match[index] += early
            self.rec.get_logger().warning(
                f"{early} message(s) of {topic} were sent by a new publisher before it matched "
                f"the recorder (publisher sequence 1..{early}): not in the bag "
                f"[{self.before_match[index]} missed so on this topic]"
            )
        if missing and self.rec.latest_only[index]:
            self.superseded[index] += missing
        elif missing:
            self.gaps[index] += missing
            self.rec.get_logger().warning(
                f"{missing} message(s) of {topic} never reached the recorder (publisher "
                f"sequence {first}..{last}) [{self.gaps[index]} lost on this topic]"
            )

    def _connect(self, index: int) -> None:
        topic = self.rec.topics[index]
        self.conns[index] = self.writer.add_connection(
            topic,
            type_name(self.rec.types[topic]),
            typestore=self.store,
            offered_qos_profiles=self.rec.offered_qos(topic),
        )

    def close(self) -> None:
        for index in range(len(self.rec.topics)):  # topics never heard are in the bag too
            if index not in self.conns:
                self._connect(index)
        missed = {t: n for t, n in zip(self.rec.topics, self.before_match, strict=True) if n}
        lost = {t: n for t, n in zip(self.rec.topics, self.gaps, strict=True) if n}
        # metadata.yaml custom_data (rosbag2): what the bag lacks, per topic
        self.writer.set_custom_data("pd_record.missed_before_match", _per_topic(missed))
        self.writer.set_custom_data("pd_record.lost", _per_topic(lost))
        self.writer.close()

    def summary(self) -> str:
        parts = []
        for i, topic in enumerate(self.rec.topics):
            lost = f", {self.gaps[i]} LOST" if self.gaps[i] else ""
            newer = f", {self.superseded[i]} superseded" if self.superseded[i] else ""
            early = self.before_match[i]
            early = f", {early} missed before a new publisher matched" if early else ""
            parts.append(f"{topic}: {self.counts[i]}{lost}{newer}{early}")
        if self.unwritten:
            parts.append(f"{self.unwritten} queued at the stop deadline NOT WRITTEN")
        return ", ".join(parts)


def _per_topic(counts: dict[str, int]) -> str:
    """`topic n, topic n` ("0" when none): a custom_data value (rosbag2 keeps strings)."""
    return ", ".join(f"{t} {n}" for t, n in counts.items()) or "0"


def parse_args(argv: list[str]) -> argparse.Namespace:
    """The recorder's own arguments (`--ros-args` sections already taken out)."""
    p = argparse.ArgumentParser(
        prog="pd_record",
        description=__doc__.split("\n\n")[0],
        epilog="ROS arguments go in a --ros-args section, e.g. --ros-args -r __ns:=/vehicle1",
    )
    p.add_argument(
        "topics",
        nargs="*",
        default=list(names.RECORD_TOPICS),
        help=f"topics to record (default: {' '.join(names.RECORD_TOPICS)})",
    )
    p.add_argument(
        "-o",
        "--output",
        type=Path,
        default=None,
        help="bag folder to create (default bags/pd_<date>-<time>)",
    )
    p.add_argument(
        "--duration", type=float, default=0.0, help="stop after this many seconds (0 = Ctrl-C)"
    )
    p.add_argument(
        "--flush", type=float, default=0.5, help="close an MCAP chunk every this many seconds"
    )
    p.add_argument(
        "--discovery-timeout",
        type=float,
        default=5.0,
        help="seconds to wait for publishers of topics whose type is not known",
    )
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    try:
        own, ros_args = split_ros_args("pd_record", sys.argv[1:] if argv is None else argv)
    except UsageError as exc:
        print(exc, file=sys.stderr)
        return 2
    args = parse_args(own)
    bag = args.output or Path("bags") / datetime.now().strftime("pd_%Y%m%d-%H%M%S")
    if bag.exists():
        print(f"pd_record: {bag} exists already; choose another --output", file=sys.stderr)
        return 2
    if not args.flush > 0:
        print(f"pd_record: --flush must be > 0, got {args.flush}", file=sys.stderr)
        return 2
    bag.parent.mkdir(parents=True, exist_ok=True)
    stop = threading.Event()
    # Our own handlers, first: rclpy's would shut the context down before the bag is closed. A
    # second signal (launch's SIGTERM after SIGINT) only sets the flag again.
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    rclpy.init(args=["pd_record", *ros_args], signal_handler_options=SignalHandlerOptions.NO)
    sink: queue.SimpleQueue = queue.SimpleQueue()
    node = writer = None
    executor = SingleThreadedExecutor()
    try:
        node = Recorder(args.topics, sink, args.discovery_timeout, stop)
        writer = BagWriter(bag, node, sink, args.flush)
        writer.start()
        node.report_on(writer)
        executor.add_node(node)
        node.get_logger().info(f"recording {', '.join(node.topics)} to {bag}")
        t_end = time.monotonic() + args.duration if args.duration > 0 else float("inf")
        while not stop.is_set() and time.monotonic() < t_end and writer.is_alive():
            executor.spin_once(timeout_sec=0.05)
        # What DDS delivered before the stop is still in the readers' queues (a flight's last
        # messages, e.g. the episode result, come right before a stop): take it too.
        t_take = time.monotonic() + TAKE_S
        while time.monotonic() < t_take and writer.is_alive():
            executor.spin_once(timeout_sec=0.02)
    finally:
        if node is not None:
            node.freeze_qos()  # the last graph query: the writer never touches the node again
            executor.remove_node(node)
            node.destroy_node()  # no more messages; what is queued gets written
        executor.shutdown(timeout_sec=0.2)
        if writer is not None:
            writer.stop()
            writer.join()
            writer.close()
            print(f"pd_record: closed {bag} ({writer.summary()})", flush=True)
        rclpy.try_shutdown()
        # Stopped: the bag is closed. A later SIGINT/SIGTERM (launch's SIGTERM after SIGINT)
        # must not kill the interpreter's teardown, which puts default handlers back.
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, signal.SIG_IGN)
    if writer.error is not None:
        print(f"pd_record: writing {bag} failed: {writer.error!r}", file=sys.stderr)
        return 1
    return 1 if any(writer.gaps) or writer.unwritten else 0


if __name__ == "__main__":
    sys.exit(main())
