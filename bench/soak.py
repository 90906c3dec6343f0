"""Soak: N minutes of lockstep auto_restart over DDS, with a recorder; losses and memory growth.

    python bench/soak.py --minutes 10 [--controller dqn|zemzev|...] [--no-record]

Starts pd_sim_node (lockstep, auto_restart), pd_policy_node and pd_record as processes on a ROS
domain of their own, listens to everything with KEEP_ALL subscriptions, and reports, side by side:
episodes and landings; messages lost anywhere (publisher sequence gaps at the probe, commands the
simulator counted lost, the recorder's gaps and its bag against the probe's counts); commands
missed or rejected by the simulator; and each node's resident memory at the start and end with its
slope over the second half of the run (MiB per minute; flat = no leak). Not part of `make test`.
Target: 10 minutes, 0 lost, flat RSS.
"""

from __future__ import annotations

import argparse
import re
import signal
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from pd_bringup.bag import read_bag
from pd_interfaces.msg import EpisodeResult, LanderState, ThrustCommand
from pd_interfaces.srv import ResetEpisode
from pd_ros_common import names, qos
from pd_ros_common.convert import reset_request
from pd_ros_common.domain import claim_domain_id
from pd_ros_common.gaps import SequenceGaps
from pd_ros_common.process import Supervisor, executable
from pd_ros_common.session import RosSession

KEEP_ALL = QoSProfile(
    history=HistoryPolicy.KEEP_ALL,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
SAMPLE_S = 5.0


def rss_mib(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


class Probe:
    """Counts every state and command (with sequence gaps) and keeps every result."""

    def __init__(self, node: Node) -> None:
        self.counts = {names.STATE_TOPIC: 0, names.COMMAND_TOPIC: 0}
        self.gaps = {t: SequenceGaps() for t in self.counts}
        self.results: list[EpisodeResult] = []
        for topic, cls in ((names.STATE_TOPIC, LanderState), (names.COMMAND_TOPIC, ThrustCommand)):
            node.create_subscription(cls, topic, self._counter(topic), KEEP_ALL, raw=True)
        node.create_subscription(EpisodeResult, names.EPISODE_TOPIC, self.results.append,
                                 qos.EPISODE_QOS)  # fmt: skip

    def _counter(self, topic: str):
        def on_message(_raw: bytes, info) -> None:
            self.counts[topic] += 1
            self.gaps[topic].update(info)

        return on_message


def parse_args() -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--minutes", type=float, default=10.0, help="length of the soak")
    p.add_argument("--controller", default="dqn", help="pd_policy_node controller")
    p.add_argument("--no-record", action="store_true", help="without pd_record")
    p.add_argument("--out", type=Path, default=None, help="logs and bag (default: a temp dir)")
    return p.parse_args()


def last_count(pattern: str, log: str) -> int:
    found = re.findall(pattern, log)
    return int(found[-1]) if found else 0


def run(args: argparse.Namespace, out: Path, domain: int) -> int:
    sup = Supervisor(out / "logs", {"ROS_DOMAIN_ID": str(domain)})
    ros = RosSession("pd_soak", domain)
    node = ros.node
    probe = Probe(node)
    rss: dict[str, list[tuple[float, float]]] = {}
    try:
        sim = sup.node(
            "pd_sim_node", {"lockstep": True, "auto_restart": True, "start_episode": False}
        )
        pol = sup.node("pd_policy_node", {"controller": args.controller, "stats_period_s": 60.0})
        rec = None
        if not args.no_record:
            argv = [executable("pd_bringup", "pd_record"), "-o", str(out / "bag")]
            rec = sup.start("pd_record", argv)
        listeners = 3 if rec else 2
        deadline = time.monotonic() + 120.0
        reset = node.create_client(ResetEpisode, names.RESET_SERVICE)
        while not (reset.service_is_ready()
                   and node.count_subscribers(names.STATE_TOPIC) >= listeners
                   and node.count_subscribers(names.COMMAND_TOPIC) >= listeners
                   and node.count_publishers(names.COMMAND_TOPIC) >= 1):  # fmt: skip
            sup.check_alive()
            if time.monotonic() > deadline:
                print(f"the stack did not come up:\n{sup.logs()}", file=sys.stderr)
                return 1
            ros.spin_once(0.1)
        ros.spin_for(1.0)
        reset.call_async(reset_request(None, 0))
        t0 = time.monotonic()
        t_end = t0 + args.minutes * 60.0
        next_sample = t0
        print(f"soak: {args.minutes:g} min on ROS_DOMAIN_ID={domain}, output {out}", flush=True)
        while time.monotonic() < t_end:
            now = time.monotonic()
            if now >= next_sample:
                for c in sup.children:
                    rss.setdefault(c.name, []).append(((now - t0) / 60.0, rss_mib(c.pid)))
                next_sample += SAMPLE_S
                sup.check_alive()
            ros.spin_once()
        wall = time.monotonic() - t0
        # Stop the traffic (policy, then simulator), let everything in flight arrive, then stop
        # the recorder: the bag and the probe must then hold the same messages.
        pol.stop()
        sim.stop()
        ros.spin_for(2.0)
        bag_note = ""
        if rec is not None:
            rec.stop(sig=signal.SIGTERM)
            bag = read_bag(out / "bag")
            in_bag = {t: sum(1 for m in bag.messages if m[0] == "/" + t) for t in probe.counts}
            bag_note = ", ".join(
                f"{t} {n} ({probe.counts[t] - n} fewer than heard)" for t, n in in_bag.items()
            )
        report(args, probe, sim.log(), pol.log(), rec.log() if rec else "", bag_note, rss, wall)
    finally:
        sup.stop_all()
        ros.close()
    return 0


def slope(samples: list[tuple[float, float]]) -> float:
    a = np.array(samples[len(samples) // 2 :])
    if len(a) < 3:
        return float("nan")
    return float(np.polyfit(a[:, 0], a[:, 1], 1)[0])


def report(args, probe: Probe, sim_log: str, pol_log: str, rec_log: str, bag_note: str,
           rss: dict, wall: float) -> None:  # fmt: skip
    res = probe.results
    landed = sum(r.landed for r in res)
    missed = sum(r.missed_commands for r in res)
    rejected = sum(r.rejected_commands for r in res)
    sim_lost = last_count(r"\[(\d+) lost so far\]", sim_log)
    pol_missing = last_count(r"(\d+) missing \(step gaps\)", pol_log)
    rec_lost = sum(int(n) for n in re.findall(r"(\d+) LOST", rec_log))
    probe_gaps = {t: g.total for t, g in probe.gaps.items()}
    rows = [
        ("run", f"{wall / 60:.1f} min, controller {args.controller}"),
        ("episodes", f"{len(res)} ended, {landed} landed"),
        ("messages heard", ", ".join(f"{t} {n}" for t, n in probe.counts.items())),
        ("lost (probe seq gaps)", ", ".join(f"{t} {n}" for t, n in probe_gaps.items())),
        ("lost (simulator)", f"{sim_lost} commands"),
        ("lost (policy)", f"{pol_missing} states (step gaps)"),
        ("lost (recorder)", f"{rec_lost}; bag holds {bag_note or 'no bag'}"),
        ("missed / rejected", f"{missed} missed, {rejected} rejected commands (all episodes)"),
    ]
    for name, samples in rss.items():
        rows.append((f"RSS {name}", f"{samples[0][1]:.1f} -> {samples[-1][1]:.1f} MiB, "
                     f"slope {slope(samples):+.3f} MiB/min (second half)"))  # fmt: skip
    width = max(len(k) for k, _ in rows)
    print("\n".join(f"  {k:<{width}}  {v}" for k, v in rows), flush=True)


def main() -> int:
    args = parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="pd_soak_"))
    out.mkdir(parents=True, exist_ok=True)
    domain, _lock = claim_domain_id("ROS_DOMAIN_ID")
    return run(args, out, domain)


if __name__ == "__main__":
    sys.exit(main())
