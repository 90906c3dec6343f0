"""Loop latency over DDS and the simulator's period jitter (not part of `make test`).

1. Latency: this process plays the simulator (pd_core.sim.Simulator, closed loop) and publishes
   /lander/state; a real pd_policy_node process answers on /lander/thrust_cmd. Measured: time from
   just before `publish(state)` to the command's arrival in our callback, over --steps steps (one
   at a time, ping-pong). Target p99 < 5 ms.
2. Jitter: a real pd_sim_node at 5 Hz (auto_restart, no policy); measured: |inter-arrival - 200 ms|
   of /lander/state at a subscriber over --jitter-s seconds (this includes DDS delivery and our
   own wake-up, so it bounds the simulator's own timer jitter from above). Target p99 < 2 ms.

    scripts/in_env.sh python bench/loop_latency.py [--steps 1000] [--jitter-s 60] [--model PATH]

Prints figures and a JSON line; exits 0 whether or not targets are met (it reports, CI does not
gate on it).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from pd_core.runtime.build import shipped_policy
from pd_core.sim import Command, Simulator
from pd_core.ticker import percentiles_ms
from pd_interfaces.msg import LanderState, ThrustCommand
from pd_ros_common import names
from pd_ros_common.convert import state_msg
from pd_ros_common.domain import claim_domain_id
from pd_ros_common.process import ProcessError, Supervisor
from pd_ros_common.qos import LOOP_PUB_QOS, LOOP_SUB_QOS
from pd_ros_common.session import RosSession


def parse_args() -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--steps", type=int, default=1000, help="latency samples (steps)")
    p.add_argument("--jitter-s", type=float, default=60.0, help="seconds of 5 Hz states to time")
    p.add_argument("--model", default="", help="policy file (default: shipped, else untrained)")
    p.add_argument(
        "--tick-priority", type=int, default=0, help="pd_sim_node tick_priority (SCHED_FIFO)"
    )
    return p.parse_args()


def model_path(arg: str, tmp: Path) -> tuple[str, str]:
    if arg:
        return arg, "given"
    shipped = shipped_policy()
    if shipped.is_file():
        return str(shipped), "shipped"
    import torch  # optional heavy dependency: only without a shipped model

    from pd_core.dqn.network import QNetwork
    from pd_core.runtime.policy_file import save_policy

    torch.manual_seed(0)
    return str(save_policy(tmp / "untrained.pt", QNetwork())), "untrained (no shipped model yet)"


def measure_latency(args, sup: Supervisor, ros: RosSession, model: str, kind: str) -> dict:
    """State published -> command received, through a real pd_policy_node process."""
    node = ros.node
    pol = sup.node("pd_policy_node", {"model_path": model, "stats_period_s": 0.0})
    got: list[tuple[float, ThrustCommand]] = []
    node.create_subscription(
        ThrustCommand,
        names.COMMAND_TOPIC,
        lambda m: got.append((time.perf_counter(), m)),
        LOOP_SUB_QOS,
    )
    pub = node.create_publisher(LanderState, names.STATE_TOPIC, LOOP_PUB_QOS)
    deadline = time.monotonic() + 60
    while pub.get_subscription_count() < 1 or node.count_publishers(names.COMMAND_TOPIC) < 1:
        if time.monotonic() > deadline or not pol.alive:
            raise ProcessError(f"policy node did not come up:\n{pol.tail()}")
        ros.spin_once()
    time.sleep(0.5)
    sim = Simulator(seed=0)
    sim.reset()
    lat: list[float] = []
    lost = 0
    for i in range(args.steps + 20):  # 20 warm-up steps, not counted
        if not sim.flying:
            sim.reset()
        msg = state_msg(sim.episode, sim.step, sim.time_s, sim.state, sim.status)
        got.clear()
        t0 = time.perf_counter()
        pub.publish(msg)
        end = t0 + 1.0
        while not got and time.perf_counter() < end:
            ros.spin_once(0.1)
        if not got:
            lost += 1
            sim.advance()
            continue
        t1, cmd = got[0]
        if i >= 20:
            lat.append(t1 - t0)
        t = cmd.thrust
        sim.submit(Command(cmd.episode, cmd.step, cmd.action, (t.x, t.y, t.z)))
        sim.advance()
        time.sleep(0.002)
    q = percentiles_ms(lat)
    print(
        f"state published -> command received over DDS ({kind} model), "
        f"{q['n']} steps: p50 {q['p50']:.3f} ms, p99 {q['p99']:.3f} ms, max {q['max']:.3f} ms"
        f"  [target p99 < 5 ms: {'met' if q['p99'] < 5 else 'NOT met'}]; lost {lost}",
        flush=True,
    )
    pol.stop()
    return {**q, "lost": lost}


def measure_jitter(args, sup: Supervisor, ros: RosSession) -> dict:
    """Period jitter of a real pd_sim_node process at 5 Hz, at a subscriber."""
    node = ros.node
    arrivals: list[float] = []
    node.create_subscription(
        LanderState, names.STATE_TOPIC, lambda m: arrivals.append(time.monotonic()), LOOP_SUB_QOS
    )
    # No policy here: the simulator flies at once (start_wait_s 0), holding zero thrust.
    params = {"auto_restart": True, "start_wait_s": 0.0, "tick_priority": args.tick_priority}
    simp = sup.node("pd_sim_node", params)
    deadline = time.monotonic() + 60
    while len(arrivals) < 3:
        if time.monotonic() > deadline or not simp.alive:
            raise ProcessError(f"simulator did not come up:\n{simp.tail()}")
        ros.spin_once()
    arrivals.clear()
    ros.spin_for(args.jitter_s)
    q = percentiles_ms(np.abs(np.diff(arrivals) - 0.2))
    rate = (len(arrivals) - 1) / (arrivals[-1] - arrivals[0])
    print(
        f"simulator period jitter at 5 Hz (|period - 200 ms| at a subscriber), "
        f"{q['n']} periods: p50 {q['p50']:.3f} ms, p99 {q['p99']:.3f} ms, "
        f"max {q['max']:.3f} ms; mean rate {rate:.4f} Hz"
        f"  [target p99 < 2 ms: {'met' if q['p99'] < 2 else 'NOT met'}]",
        flush=True,
    )
    return {**q, "rate_hz": rate, "tick_priority": args.tick_priority}


def main() -> int:
    args = parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="pd_bench_"))
    domain, _lock = claim_domain_id("ROS_DOMAIN_ID")
    sup = Supervisor(tmp, {"ROS_DOMAIN_ID": str(domain)})
    model, model_kind = model_path(args.model, tmp)
    ros = RosSession("pd_bench", domain)
    report: dict = {"model": model_kind, "cpu_count": os.cpu_count()}
    try:
        report["latency_ms"] = measure_latency(args, sup, ros, model, model_kind)
        if args.jitter_s > 0:
            report["jitter_ms"] = measure_jitter(args, sup, ros)
        print(json.dumps(report))
    except ProcessError as exc:
        print(exc, file=sys.stderr)
        return 1
    finally:
        sup.stop_all()
        ros.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
