"""pd_replay: publish a bag's messages with their recorded timing (or `--rate` times faster).

    pd_replay bags/run1
    pd_replay bags/run1 --topics /lander/state --rate 10
    pd_replay bags/run1 --topics /lander/state --remap /lander/state:=/replay/state
    pd_replay bags/run1 --no-wait --ros-args -r __node:=pd_replay_2

The raw CDR bytes of the bag are published unchanged, each topic with the QoS its recorded
publishers offered (`offered_qos_profiles`: /lander/episode stays TRANSIENT_LOCAL, so a latched
subscriber matches). A bag whose recorder was killed (no metadata.yaml, no MCAP footer) is
recovered up to its last complete chunk; a bag that cannot be read at all is one line on stderr
(exit status 2). The first message waits until every replayed topic has a subscriber
(`--wait-subscribers N`: N of them), so a replay into a node started at the same time does not
lose its first seconds. After `--wait-timeout` (30 s) the replay starts anyway, naming the topics
nobody subscribes to; if no topic has a subscriber at all, it publishes nothing and exits 1.
`--no-wait` (or `--wait-subscribers 0`) publishes at once. Topics only viewers read (odometry,
paths, /diagnostics, /clock: `viewer_only`) are not waited for, unless the replay has nothing
else. ROS arguments (`--ros-args ...`) may come anywhere on the command line.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import rclpy
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node

from pd_bringup.bag import BagError, message_class, read_bag, replay_qos
from pd_ros_common import names
from pd_ros_common.cli import UsageError, split_ros_args
from pd_ros_common.publishing import PublishTimeout, publish_acked

WAIT_TIMEOUT_S = 30.0


def parse_args(argv: list[str]) -> argparse.Namespace:
    """The replayer's own arguments (`--ros-args` sections already taken out)."""
    p = argparse.ArgumentParser(
        prog="pd_replay",
        description=__doc__.split("\n\n")[0],
        epilog="ROS arguments go in a --ros-args section, e.g. --ros-args -r __node:=replay2",
    )
    p.add_argument("bag", type=Path, help="bag folder (rosbag2, MCAP or SQLite3)")
    p.add_argument("--topics", nargs="+", default=None, help="only these topics (default all)")
    p.add_argument("--rate", type=float, default=1.0, help="playback speed factor (default 1.0)")
    p.add_argument(
        "--remap",
        action="append",
        default=[],
        metavar="FROM:=TO",
        help="publish topic FROM under the name TO (repeatable)",
    )
    p.add_argument(
        "--wait-subscribers",
        type=int,
        default=1,
        metavar="N",
        help="before the first message, wait until each topic has N subscribers (default 1)",
    )
    p.add_argument(
        "--no-wait",
        dest="wait_subscribers",
        action="store_const",
        const=0,
        help="publish at once, subscribers or not (= --wait-subscribers 0)",
    )
    p.add_argument(
        "--wait-timeout",
        type=float,
        default=WAIT_TIMEOUT_S,
        help=f"seconds for that wait (default {WAIT_TIMEOUT_S:g}); then it replays anyway",
    )
    return p.parse_args(argv)


def viewer_only(topic: str) -> bool:
    """True for a topic nobody in the stack subscribes to (in any namespace)."""
    if topic in (names.DIAGNOSTICS_TOPIC, names.CLOCK_TOPIC):
        return True
    return any(topic.endswith("/" + t) for t in names.VIEW_TOPICS)


def wait_for_subscribers(pubs: dict[str, Any], wanted: int, timeout_s: float) -> bool:
    """Wait until each publisher has `wanted` subscribers, at most `timeout_s`. False if none
    has any then (nothing would hear the replay); topics short of `wanted` are named."""

    def short() -> list[str]:
        return [t for t, p in pubs.items() if p.get_subscription_count() < wanted]

    print(
        f"pd_replay: waiting for {wanted} subscriber(s) of {', '.join(short()) or 'no topic'} "
        f"(up to {timeout_s:g} s; --no-wait to publish at once)",
        flush=True,
    )
    deadline = time.monotonic() + timeout_s
    while short() and time.monotonic() < deadline:
        time.sleep(0.05)
    missing = short()
    if missing and all(p.get_subscription_count() == 0 for p in pubs.values()):
        print(
            f"pd_replay: no subscriber to any replayed topic after {timeout_s:g} s; nothing "
            "published (--no-wait to publish anyway)",
            file=sys.stderr,
            flush=True,
        )
        return False
    if missing:
        print(
            f"pd_replay: fewer than {wanted} subscriber(s) after {timeout_s:g} s on "
            f"{', '.join(missing)}; replaying anyway",
            flush=True,
        )
    return True


class Replayer(Node):
    def __init__(self) -> None:
        super().__init__("pd_replay")


def main(argv: list[str] | None = None) -> int:
    try:
        own, ros_args = split_ros_args("pd_replay", sys.argv[1:] if argv is None else argv)
    except UsageError as exc:
        print(exc, file=sys.stderr)
        return 2
    args = parse_args(own)
    if not args.rate > 0:
        print(f"pd_replay: --rate must be > 0, got {args.rate}", file=sys.stderr)
        return 2
    remap = {}
    for r in args.remap:
        src, sep, dst = r.partition(":=")
        if not sep or not src or not dst:
            print(f"pd_replay: --remap wants FROM:=TO, got {r!r}", file=sys.stderr)
            return 2
        remap[src] = dst
    try:
        bag = read_bag(args.bag, args.topics)
    except (BagError, OSError, ValueError, KeyError, MemoryError) as exc:
        print(f"pd_replay: cannot read {args.bag}: {exc}", file=sys.stderr)
        return 2
    types = {t: v for t, v in bag.topics.items() if args.topics is None or t in args.topics}
    if not types:
        damaged = " (no metadata or footer, nothing recoverable)" if bag.recovered else ""
        print(f"pd_replay: no matching topics in {args.bag}{damaged}", file=sys.stderr)
        return 2
    if bag.recovered:
        print(
            f"pd_replay: {args.bag} has no metadata or footer (recorder killed?); "
            f"recovered {len(bag.messages)} messages",
            flush=True,
        )

    rclpy.init(args=["pd_replay", *ros_args])
    node = Replayer()
    sent = 0
    try:
        pubs = {
            t: node.create_publisher(message_class(m), remap.get(t, t), replay_qos(offered))
            for t, (m, offered) in types.items()
        }
        waited = {t: p for t, p in pubs.items() if not viewer_only(t)} or pubs
        if args.wait_subscribers > 0 and not wait_for_subscribers(
            waited, args.wait_subscribers, args.wait_timeout
        ):
            return 1
        t0_wall = time.monotonic()
        t0_bag = None
        for topic, stamp, raw in bag.messages:
            if t0_bag is None:
                t0_bag = stamp
            delay = t0_wall + (stamp - t0_bag) * 1e-9 / args.rate - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            publish_acked(pubs[topic], bytes(raw))
            sent += 1
        for p in pubs.values():
            p.wait_for_all_acked(Duration(seconds=5))
        print(f"pd_replay: published {sent} messages from {args.bag}", flush=True)
    except (KeyboardInterrupt, ExternalShutdownException):
        print(f"pd_replay: interrupted after {sent} messages", flush=True)
    except PublishTimeout as exc:
        print(f"pd_replay: stopped after {sent} messages: {exc}", file=sys.stderr)
        return 1
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
