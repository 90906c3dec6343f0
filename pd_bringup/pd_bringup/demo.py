"""pd_demo: one closed-loop landing over ROS 2, end to end (what `make demo` runs).

1. starts pd_sim_node, pd_policy_node, pd_ocp_node (managed nodes, waiting unconfigured) and
   pd_record as separate processes over DDS (a ROS domain of their own, logs under <out>/logs),
   and brings the three up with the lifecycle manager (`pd_bringup.lifecycle_manager`:
   configure OCP, policy, simulator, then activate them in that order), printing every
   transition; the manager watches them through the flight;
2. starts the episode with /sim/reset (Table 3 sampled with --seed by the simulator, which
   replies with the initial state) and asks /ocp/compute_trajectory for the optimal trajectory
   from that state, while the lander flies in closed loop at the real 5 Hz (--fast: lockstep, as
   fast as the policy answers), recorded to an MCAP bag;
3. prints the touchdown state, fuel against the OCP's fuel and whether it landed, writes a PNG of
   the flight beside the OCP's trajectory and one drawn from the bag alone (bag.png: lander/path
   and ocp/plan, as `scripts/bag_to_png.py` draws it), takes the stack down through the manager
   (deactivate, cleanup, shutdown in reverse order; the transitions are in the bag too), stops
   every process it started and exits 0
   (1 if the stack failed to fly the episode; landing or crashing both count as flown).

It starts its own nodes on a domain of its own: a `--ros-args` section (as `ros2 run` or a launch
file may add) is accepted and ignored, with a note.
"""

from __future__ import annotations

import argparse
import sys
import time
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

from pd_bringup import bag_plot
from pd_bringup.bag import BagError, read_bag
from pd_bringup.flight import FlightClient, FlightError
from pd_bringup.guidance import bag_counts, node_counts
from pd_bringup.lifecycle_manager import LifecycleManager
from pd_core.config import DT_S, MAX_EPISODE_TIME_S, REWARD
from pd_core.plots import flight_vs_ocp
from pd_ros_common import names
from pd_ros_common.cli import UsageError, split_ros_args
from pd_ros_common.convert import final_state
from pd_ros_common.domain import claim_domain_id
from pd_ros_common.lifecycle import TRANSITION_EVENT
from pd_ros_common.process import ProcessError, Supervisor, executable
from pd_ros_common.session import SERVICE_SETTLE_S

START_TIMEOUT_S = 60.0  # node start-up on a busy 2-core machine (torch import)
RECORDED_TIMEOUT_S = 15.0  # the recorder's last messages after the flight, under load


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    """pd_demo's own arguments; `--ros-args` sections are taken out first (UsageError if bad)."""
    own, _ = split_ros_args("pd_demo", sys.argv[1:] if argv is None else argv)
    p = argparse.ArgumentParser(prog="pd_demo", description=__doc__.split("\n\n")[0])
    p.add_argument("--fast", action="store_true", help="lockstep instead of the real 5 Hz")
    p.add_argument(
        "--seed", type=int, default=0, help="seed of the episode (Table 3 state and disturbance)"
    )
    p.add_argument("--model", default="", help="policy file (default: the shipped model)")
    p.add_argument(
        "--controller",
        default="dqn",
        help="pd_policy_node's controller: dqn (--model), zemzev, mpc-fuel, mpc-energy",
    )
    p.add_argument("--out", type=Path, default=None, help="output folder (default out/demo-<time>)")
    p.add_argument("--method", default="", help="OCP method (default: pd_ocp_node's)")
    p.add_argument(
        "--objective",
        choices=("energy", "fuel"),
        default="energy",
        help="the OCP landing flown beside the policy: energy (Eq. 4, the paper's) or fuel "
        "(the fuel-optimal landing the shipped policy's teacher plans)",
    )
    return p.parse_args(own)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    try:
        args = parse_args(argv)
    except UsageError as exc:
        print(exc, file=sys.stderr)
        return 2
    if "--ros-args" in argv:
        print("pd_demo: --ros-args ignored (the demo starts its own nodes)", flush=True)
    try:
        return run(args)
    except (FlightError, ProcessError) as exc:
        print(f"pd_demo: FAILED: {exc}", file=sys.stderr, flush=True)
        return 1
    except KeyboardInterrupt:
        print("pd_demo: interrupted", file=sys.stderr)
        return 130


def start_stack(sup: Supervisor, args: argparse.Namespace, bag: Path) -> None:
    policy = {"controller": args.controller, **({"model_path": args.model} if args.model else {})}
    managed = {"autostart": False}  # the lifecycle manager brings them up
    sup.node("pd_sim_node", {"lockstep": args.fast, "start_episode": False, **managed})
    sup.node("pd_policy_node", {**policy, **managed})
    sup.node("pd_ocp_node", managed)
    sup.start("pd_record", [executable("pd_bringup", "pd_record"), "-o", str(bag)])


def bring_up(flight: FlightClient, sup: Supervisor) -> LifecycleManager:
    """The lifecycle manager on the flight client's node, the stack brought up by it (every
    transition printed) once the recorder hears the transition events."""
    manager = LifecycleManager(
        flight.node,
        lambda pred, timeout_s: flight.spin_until(pred, timeout_s, sup.check_alive),
        names.MANAGED_NODES,
        say=lambda line: print(f"  lifecycle: {line}", flush=True),
    )
    missing = manager.wait_for_services(START_TIMEOUT_S)
    if missing:
        raise FlightError(f"no lifecycle services of {', '.join(missing)}")
    # a reliable, volatile writer sends only to readers it has matched: the recorder's
    # subscriptions must have matched the transition-event writers before the first transition
    hears = {t: 1 for t in names.TRANSITION_TOPICS}
    if not flight.spin_until(
        lambda: flight.reported_at_least("writers", hears), START_TIMEOUT_S, sup.check_alive
    ):
        raise FlightError("pd_record does not hear the nodes' transition events")
    flight.spin_for(SERVICE_SETTLE_S)  # discovery both ways (pd_ros_common.session)
    if not manager.startup():
        raise FlightError(f"the stack did not come up: {manager.failure}")
    return manager


def watch(manager: LifecycleManager, sup: Supervisor) -> None:
    """FlightError when a node failed (the manager has taken the others down)."""
    sup.check_alive()
    failure = manager.watch()
    if failure is not None:
        raise FlightError(failure)


def take_down(manager: LifecycleManager, flight: FlightClient | None) -> None:
    """Deactivate, cleanup and shutdown in reverse order; then let the recorder write every
    transition event the manager heard."""
    print("pd_demo: taking the stack down", flush=True)
    manager.shutdown()
    if flight is not None:
        heard = {TRANSITION_EVENT.format(n): len(e) for n, e in manager.events.items()}
        if not flight.spin_until(lambda: flight.recorded_at_least(heard), RECORDED_TIMEOUT_S):
            print("pd_demo: the recorder did not report every transition event", flush=True)


def flown_by(sup: Supervisor) -> str:
    """What pd_policy_node said it flies: its "policy ready:" line, up to the network's shape."""
    policy = next(c for c in sup.children if c.name == "pd_policy_node")
    for line in policy.log().splitlines():
        if "policy ready: " in line:
            return line.split("policy ready: ", 1)[1].split(" (", 1)[0]
    return "(not said in its log)"


def run(args: argparse.Namespace) -> int:
    out = args.out or Path("out") / datetime.now().strftime("demo-%Y%m%d-%H%M%S")
    out.mkdir(parents=True, exist_ok=True)
    bag = out / "bag"
    domain, _lock = claim_domain_id("ROS_DOMAIN_ID")
    mode = "lockstep (FAST)" if args.fast else "real time, 5 Hz"
    print(f"pd_demo: {mode}, seed {args.seed}, ROS_DOMAIN_ID={domain}, output {out}", flush=True)
    sup = Supervisor(out / "logs", {"ROS_DOMAIN_ID": str(domain)})
    flight = manager = None
    t_start = time.monotonic()
    try:
        start_stack(sup, args, bag)
        flight = FlightClient(domain)
        manager = bring_up(flight, sup)
        if not flight.spin_until(flight.stack_ready, START_TIMEOUT_S, sup.check_alive):
            tails = "\n".join(f"  {c.name}:\n{c.tail(5)}" for c in sup.children)
            raise FlightError(f"the stack did not come up within {START_TIMEOUT_S:g} s\n{tails}")
        # the writers have matched every reader (stack_ready); a service's response writer may
        # still lag its client (pd_ros_common.session.wait_for_server)
        flight.spin_for(SERVICE_SETTLE_S)
        print(f"pd_demo: 4 processes up after {time.monotonic() - t_start:.1f} s", flush=True)
        print(f"  policy: {flown_by(sup)}", flush=True)

        episode, s0 = flight.reset(args.seed)
        print(f"  episode {episode} flying ({mode}) from x = {_fmt(s0[0:3])} m, "
              f"v = {_fmt(s0[3:6])} m/s, m = {s0[6]:.1f} kg", flush=True)  # fmt: skip
        t_fly = time.monotonic()
        ocp = flight.solve_ocp(s0, method=args.method, objective=args.objective)
        print_ocp(ocp, args.objective)
        budget = 60.0 if args.fast else MAX_EPISODE_TIME_S + 30.0
        result = flight.result_of(episode, budget, lambda: watch(manager, sup))
        wall = time.monotonic() - t_fly
        states, thrust = flight.trajectory(episode)
        if not flight.spin_until(flight.recorded_all, RECORDED_TIMEOUT_S, sup.check_alive):
            wait = f"{RECORDED_TIMEOUT_S:g} s"
            print(f"pd_demo: the recorder did not report every message in {wait}", flush=True)
    finally:
        if manager is not None:
            take_down(manager, flight)
        sup.stop_all(first="pd_record")  # the recorder first: it closes the bag
        if flight is not None:
            flight.close()
    print_report(result, ocp, wall, args.objective)
    recorded = read_bag(bag)
    counts = {t: 0 for t in recorded.topics}
    for topic, _, _ in recorded.messages:
        counts[topic] += 1
    print(f"  bag {bag}: " + ", ".join(f"{t} {n}" for t, n in counts.items()))
    print_guidance(bag, sup)
    title = (
        f"seed {args.seed}, {args.controller}, {mode}: "
        f"{'landed' if result.landed else 'not landed'}, fuel {result.fuel:.1f} kg"
        + (f" (OCP {ocp.fuel:.1f} kg)" if ocp.success else "")
    )
    png = flight_vs_ocp(
        out / "flight.png",
        states,
        thrust,
        FlightClient.ocp_arrays(ocp),
        title,
        dt_s=DT_S,
        flight_label=f"flight over ROS 2 ({args.controller})",
    )
    print(f"  plot {png}")
    try:  # what a viewer sees, from the bag alone (lander/path and ocp/plan)
        print(f"  bag plot {bag_plot.render(bag, out / 'bag.png')}")
    except BagError as exc:
        print(f"  bag plot: none ({exc})")
    print("pd_demo: done, every process stopped", flush=True)
    return 0


def print_guidance(bag: Path, sup: Supervisor) -> None:
    """Who decided the commands, from the bag, beside the policy node's own count."""
    in_bag = bag_counts(bag)
    policy = next((c for c in sup.children if c.name == "pd_policy_node"), None)
    in_log = node_counts(policy.log()) if policy is not None else None
    said = ", ".join(f"{k} {v}" for k, v in in_bag.items())
    agree = "equal to" if in_log == in_bag else f"NOT equal to ({in_log})"
    print(f"  who decided (guidance_status in the bag): {said}; {agree} the policy node's count")


def _fmt(v: np.ndarray, nd: int = 2) -> str:
    return "[" + ", ".join(f"{x:.{nd}f}" for x in v) + "]"


def print_ocp(ocp: Any, objective: str) -> None:
    if not ocp.success:
        print(f"  OCP ({objective}): no trajectory ({ocp.message})", flush=True)
        return
    end = FlightClient.ocp_arrays(ocp)["states"][-1]
    print(
        f"  OCP ({objective}): {ocp.message}; time of flight {ocp.time_of_flight:.1f} s, fuel "
        f"{ocp.fuel:.1f} kg, solved in {ocp.solve_time:.2f} s; final |x| "
        f"{np.linalg.norm(end[0:3]):.3g} m, |v| {np.linalg.norm(end[3:6]):.3g} m/s",
        flush=True,
    )


def print_report(result: Any, ocp: Any, wall: float, objective: str) -> None:
    end = final_state(result)
    print(
        f"\nTouchdown after {result.time_of_flight:.1f} s simulated ({result.steps} steps, "
        f"{wall:.1f} s wall clock):"
    )
    r, v = np.linalg.norm(end[0:3]), np.linalg.norm(end[3:6])
    print(f"  position {_fmt(end[0:3], 3)} m   |x| = {r:.3f} m (< {REWARD.x_lim_m:g} m to land)")
    print(
        f"  velocity {_fmt(end[3:6], 3)} m/s |v| = {v:.3f} m/s (< {REWARD.v_lim_mps:g} m/s to land)"
    )
    print(f"  mass     {result.final_mass:.1f} kg")
    if ocp.success:
        print(
            f"  fuel     {result.fuel:.1f} kg  vs OCP ({objective}) {ocp.fuel:.1f} kg "
            f"({100.0 * (result.fuel / ocp.fuel - 1.0):+.1f} %)"
        )
    else:
        print(f"  fuel     {result.fuel:.1f} kg  (no OCP reference)")
    print(f"  LANDED: {'yes' if result.landed else 'no'} -- {result.reason}")
    print(f"  commands: rejected {result.rejected_commands}, missed {result.missed_commands}")


if __name__ == "__main__":
    sys.exit(main())
