"""pd_record: record topics to a rosbag2 bag (MCAP storage) with the `rosbags` library.

    pd_record                                  # /lander/state /lander/thrust_cmd /lander/episode
    pd_record -o bags/run1 /lander/state /lander/thrust_cmd
    pd_record --duration 30 /lander/state

Messages are taken as raw CDR (a raw subscription), so the bag holds exactly the bytes DDS
carried, stamped with their receive time (as `ros2 bag record` does). Ctrl-C or SIGTERM stops
recording: pending messages are drained, the bag is closed and its metadata.yaml written, so
nothing received is lost. Topics of unknown type are looked up in the ROS graph.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import time
from datetime import datetime
from pathlib import Path
from typing import Any

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions

from pd_bringup.bag import LOOP_QOS, message_class, open_writer, type_name, typestore
from pd_interfaces.msg import EpisodeResult, LanderState, ThrustCommand

KNOWN_TOPICS: dict[str, type] = {
    "/lander/state": LanderState,
    "/lander/thrust_cmd": ThrustCommand,
    "/lander/episode": EpisodeResult,
}
DEFAULT_TOPICS = list(KNOWN_TOPICS)

# Deep reader queue: a burst (lockstep runs) waits here rather than being dropped.
RECORD_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1000,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)


class Recorder(Node):
    """Raw subscriptions writing into an open rosbags Writer (all on the executor thread)."""

    def __init__(self, bag: Path, topics: list[str], discovery_timeout_s: float = 5.0) -> None:
        super().__init__("pd_record")
        self.bag = bag
        self.counts: dict[str, int] = dict.fromkeys(topics, 0)
        types = self._resolve_types(topics, discovery_timeout_s)
        store = typestore()
        self.writer = open_writer(bag)
        self._conns: dict[str, Any] = {}
        for topic, cls in types.items():
            self._conns[topic] = self.writer.add_connection(
                topic, type_name(cls), typestore=store, offered_qos_profiles=[LOOP_QOS]
            )
            self.create_subscription(cls, topic, self._writer_for(topic), RECORD_QOS, raw=True)
        self.get_logger().info(f"recording {', '.join(types)} to {bag}")

    def _resolve_types(self, topics: list[str], timeout_s: float) -> dict[str, type]:
        types = {t: KNOWN_TOPICS[t] for t in topics if t in KNOWN_TOPICS}
        deadline = time.monotonic() + timeout_s
        while len(types) < len(topics):
            for name, names in self.get_topic_names_and_types():
                if name in topics and name not in types:
                    types[name] = message_class(names[0])
            if len(types) == len(topics) or time.monotonic() > deadline:
                break
            time.sleep(0.1)
        missing = [t for t in topics if t not in types]
        if missing:
            raise SystemExit(
                f"pd_record: type of {', '.join(missing)} unknown (no publisher seen within "
                f"{timeout_s:g} s)"
            )
        return {t: types[t] for t in topics}

    def _writer_for(self, topic: str):
        conn = self._conns[topic]

        def write(raw: bytes) -> None:
            self.writer.write(conn, time.time_ns(), raw)
            self.counts[topic] += 1
            if self.counts[topic] == 1:
                self.get_logger().info(f"first message on {topic}")

        return write

    def close(self) -> None:
        self.writer.close()


def parse_args(argv: list[str] | None) -> tuple[argparse.Namespace, list[str]]:
    p = argparse.ArgumentParser(prog="pd_record", description=__doc__.split("\n\n")[0])
    p.add_argument("topics", nargs="*", default=DEFAULT_TOPICS, help="topics to record")
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
        "--discovery-timeout",
        type=float,
        default=5.0,
        help="seconds to wait for publishers of topics whose type is not known",
    )
    return p.parse_known_args(argv)


def main(argv: list[str] | None = None) -> int:
    args, ros_args = parse_args(sys.argv[1:] if argv is None else argv)
    bag = args.output or Path("bags") / datetime.now().strftime("pd_%Y%m%d-%H%M%S")
    if bag.exists():
        print(f"pd_record: {bag} exists already; choose another --output", file=sys.stderr)
        return 2
    bag.parent.mkdir(parents=True, exist_ok=True)

    stop = threading.Event()

    def on_signal(signum: int, _frame: Any) -> None:
        stop.set()

    # Our own handlers: rclpy's would shut the context down before the bag is closed.
    rclpy.init(args=["pd_record", *ros_args], signal_handler_options=SignalHandlerOptions.NO)
    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    node = None
    executor = SingleThreadedExecutor()
    try:
        node = Recorder(bag, args.topics, args.discovery_timeout)
        executor.add_node(node)
        t_end = time.monotonic() + args.duration if args.duration > 0 else float("inf")
        while not stop.is_set() and time.monotonic() < t_end:
            executor.spin_once(timeout_sec=0.1)
        # Drain what already arrived (queued in our subscriptions) before closing: spin until
        # nothing came for 0.3 s (at most 10 s).
        hard_end = time.monotonic() + 10.0
        quiet_since = time.monotonic()
        total = sum(node.counts.values())
        while time.monotonic() - quiet_since < 0.3 and time.monotonic() < hard_end:
            executor.spin_once(timeout_sec=0.05)
            if sum(node.counts.values()) != total:
                total = sum(node.counts.values())
                quiet_since = time.monotonic()
    finally:
        if node is not None:
            node.close()
            summary = ", ".join(f"{t}: {n}" for t, n in node.counts.items())
            print(f"pd_record: closed {bag} ({summary})", flush=True)
            executor.remove_node(node)
            node.destroy_node()
        executor.shutdown(timeout_sec=1.0)
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
