"""pd_replay: publish a bag's messages with their recorded timing (or `--rate` times faster).

    pd_replay bags/run1
    pd_replay bags/run1 --topics /lander/state --rate 10
    pd_replay bags/run1 --topics /lander/state --remap /lander/state:=/replay/state \
        --wait-subscribers 1

The raw CDR bytes of the bag are published unchanged, each topic with the QoS its recorded
publishers offered (`offered_qos_profiles`: /lander/episode stays TRANSIENT_LOCAL, so a latched
subscriber matches). A bag whose recorder was killed (no metadata.yaml, no MCAP footer) is
recovered up to its last complete chunk; a bag that cannot be read at all is one line on stderr
(exit status 2). `--wait-subscribers N` holds the first message until every replayed topic has
N subscribers (with `--wait-timeout`), so nothing is published into the void.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import rclpy
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node

from pd_bringup.bag import BagError, message_class, read_bag, replay_qos


def parse_args(argv: list[str] | None) -> tuple[argparse.Namespace, list[str]]:
    p = argparse.ArgumentParser(prog="pd_replay", description=__doc__.split("\n\n")[0])
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
        default=0,
        metavar="N",
        help="wait until each topic has N subscribers before the first message",
    )
    p.add_argument("--wait-timeout", type=float, default=30.0, help="seconds for that wait")
    return p.parse_known_args(argv)


class Replayer(Node):
    def __init__(self) -> None:
        super().__init__("pd_replay")


def main(argv: list[str] | None = None) -> int:
    args, ros_args = parse_args(sys.argv[1:] if argv is None else argv)
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
        if args.wait_subscribers > 0:
            deadline = time.monotonic() + args.wait_timeout
            while any(p.get_subscription_count() < args.wait_subscribers for p in pubs.values()):
                if time.monotonic() > deadline:
                    print("pd_replay: subscribers did not appear in time", file=sys.stderr)
                    return 1
                time.sleep(0.05)
        t0_wall = time.monotonic()
        t0_bag = None
        for topic, stamp, raw in bag.messages:
            if t0_bag is None:
                t0_bag = stamp
            delay = t0_wall + (stamp - t0_bag) * 1e-9 / args.rate - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            pubs[topic].publish(bytes(raw))
            sent += 1
        for p in pubs.values():
            p.wait_for_all_acked(Duration(seconds=5))
        print(f"pd_replay: published {sent} messages from {args.bag}", flush=True)
    except (KeyboardInterrupt, ExternalShutdownException):
        print(f"pd_replay: interrupted after {sent} messages", flush=True)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
