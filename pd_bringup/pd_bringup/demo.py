"""pd_demo: one closed-loop landing over ROS 2, end to end (what `make demo` runs).

1. starts pd_sim_node, pd_policy_node, pd_ocp_node and pd_record as separate processes over DDS
   (a ROS domain of their own, logs under <out>/logs);
2. asks /ocp/compute_trajectory for the optimal trajectory from the episode's initial state
   (Table 3 sampled with --seed, exactly as the simulator samples it);
3. starts the episode with /sim/reset and flies it in closed loop at the real 5 Hz (--fast:
   lockstep, as fast as the policy answers), recording /lander/state, /lander/thrust_cmd and
   /lander/episode to an MCAP bag;
4. prints the touchdown state, fuel against the OCP's fuel and whether it landed, writes a PNG of
   the flight beside the OCP's trajectory, stops every process it started and exits 0
   (1 if the stack failed to fly the episode; landing or crashing both count as flown).
"""

from __future__ import annotations

import argparse
import fcntl
import math
import os
import signal
import subprocess
import sys
import tempfile
import time
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

from pd_core.config import DT_S, MAX_EPISODE_TIME_S, REWARD

START_TIMEOUT_S = 60.0  # node start-up on a busy 2-core machine (torch import)


class DemoError(RuntimeError):
    """The stack did not do its part; the message says which and where its log is."""


# ---------------------------------------------------------------------------------- processes
def executable(package: str, name: str) -> str:
    """<prefix>/lib/<package>/<name> on AMENT_PREFIX_PATH (where `ros2 run` looks)."""
    for prefix in filter(None, os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)):
        path = Path(prefix) / "lib" / package / name
        if path.is_file() and os.access(path, os.X_OK):
            return str(path)
    raise DemoError(f"{package}/{name} is not installed (run `make setup`, then `source env.sh`)")


class Child:
    def __init__(self, name: str, argv: list[str], log_dir: Path, env: dict[str, str]) -> None:
        self.name = name
        self.log_path = log_dir / f"{name}.log"
        self._log = open(self.log_path, "wb")  # noqa: SIM115 (closed in stop)
        self.proc = subprocess.Popen(
            argv, stdout=self._log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, env=env
        )

    def alive(self) -> bool:
        return self.proc.poll() is None

    def tail(self, n: int = 15) -> str:
        lines = self.log_path.read_text(errors="replace").splitlines()[-n:]
        return "\n".join(f"    {line}" for line in lines)

    def stop(self, sig: int = signal.SIGINT, timeout_s: float = 10.0) -> int | None:
        if self.alive():
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5.0)
        self._log.close()
        return self.proc.returncode


def claim_domain_id() -> tuple[int, int | None]:
    """$ROS_DOMAIN_ID if set, else a free id in 1..101 locked like tests/integration/conftest.py
    (so a demo and a test run never share a domain)."""
    if os.environ.get("ROS_DOMAIN_ID"):
        return int(os.environ["ROS_DOMAIN_ID"]), None
    lock_dir = Path(tempfile.gettempdir()) / "pd_ros_domains"
    lock_dir.mkdir(mode=0o777, exist_ok=True)
    for i in range(101):
        domain = 1 + (os.getpid() + i) % 101
        fd = os.open(lock_dir / f"{domain}.lock", os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return domain, fd
        except OSError:
            os.close(fd)
    raise DemoError("no free ROS domain id in 1..101")


# ---------------------------------------------------------------------------------- ROS side
class Flight:
    """The demo's own node: service clients and a record of states, commands and the result."""

    def __init__(self, context: Any) -> None:
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

        from pd_interfaces.msg import EpisodeResult, LanderState, ThrustCommand
        from pd_interfaces.srv import ComputeTrajectory, ResetEpisode

        qos = QoSProfile(
            history=HistoryPolicy.KEEP_LAST,
            depth=1000,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.VOLATILE,
        )
        self.node = Node("pd_demo", context=context)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.states: list[Any] = []
        self.commands: list[Any] = []
        self.results: list[Any] = []
        self.node.create_subscription(LanderState, "/lander/state", self.states.append, qos)
        self.node.create_subscription(
            ThrustCommand, "/lander/thrust_cmd", self.commands.append, qos
        )
        self.node.create_subscription(EpisodeResult, "/lander/episode", self.results.append, qos)
        self.reset_cli = self.node.create_client(ResetEpisode, "/sim/reset")
        self.ocp_cli = self.node.create_client(ComputeTrajectory, "/ocp/compute_trajectory")
        self.ResetEpisode = ResetEpisode
        self.ComputeTrajectory = ComputeTrajectory

    def spin_until(self, predicate, timeout_s: float, children: list[Child] = ()) -> bool:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if predicate():
                return True
            for c in children:
                if not c.alive():
                    raise DemoError(f"{c.name} exited ({c.proc.returncode}):\n{c.tail()}")
            self.executor.spin_once(timeout_sec=0.05)
        return bool(predicate())

    def call(self, client, request, timeout_s: float):
        future = client.call_async(request)
        if not self.spin_until(future.done, timeout_s):
            raise DemoError(f"{client.srv_name}: no answer within {timeout_s:g} s")
        return future.result()

    def close(self) -> None:
        self.executor.remove_node(self.node)
        self.node.destroy_node()
        self.executor.shutdown(timeout_sec=1.0)


def _vec(v: Any) -> np.ndarray:
    return np.array([v.x, v.y, v.z])


def _fmt(v: np.ndarray, nd: int = 2) -> str:
    return "[" + ", ".join(f"{x:.{nd}f}" for x in v) + "]"


# ---------------------------------------------------------------------------------- plot
def plot(path: Path, states: np.ndarray, thrust: np.ndarray, ocp: Any, title: str) -> Path:
    """Flight (left) beside the OCP (right): position, velocity, thrust against time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.arange(len(states)) * DT_S
    ocp_states = np.array(
        [
            [*_vec(p), *_vec(v), m]
            for p, v, m in zip(ocp.positions, ocp.velocities, ocp.masses, strict=True)
        ]
    )
    ocp_thrust = np.array([_vec(u) for u in ocp.thrust])
    fig, ax = plt.subplots(3, 2, figsize=(12, 9), sharex=True, sharey="row")
    names = ("i (downrange)", "j (crossrange)", "k (altitude)")
    cols = [
        ("flight over ROS 2 (DQN policy)", t, states, t[:-1], thrust, "post"),
        (
            "optimal trajectory (/ocp/compute_trajectory)",
            np.asarray(ocp.state_times),
            ocp_states,
            np.asarray(ocp.control_times),
            ocp_thrust,
            None,
        ),
    ]
    for c, (head, ts, s, tu, u, where) in enumerate(cols):
        for k in range(3):
            if len(s):
                ax[0, c].plot(ts, s[:, k], label=names[k])
                ax[1, c].plot(ts, s[:, 3 + k], label=names[k])
            if len(u):
                if where:
                    ax[2, c].step(tu, u[:, k], where=where, label=f"T{k + 1}")
                else:
                    ax[2, c].plot(tu, u[:, k], ".-", ms=3, label=f"T{k + 1}")
        ax[0, c].set_title(head)
        for r, ylabel in enumerate(("position (m)", "velocity (m/s)", "thrust (N)")):
            ax[r, c].axhline(0.0, color="grey", lw=0.7)
            ax[r, c].legend(fontsize=7)
            if c == 0:
                ax[r, c].set_ylabel(ylabel)
        ax[2, c].set_xlabel("time (s)")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


# ---------------------------------------------------------------------------------- main
def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="pd_demo", description=__doc__.split("\n\n")[0])
    p.add_argument("--fast", action="store_true", help="lockstep instead of the real 5 Hz")
    p.add_argument(
        "--seed", type=int, default=0, help="seed of the episode (Table 3 state and disturbance)"
    )
    p.add_argument("--model", default="", help="policy file (default: the shipped model)")
    p.add_argument("--out", type=Path, default=None, help="output folder (default out/demo-<time>)")
    p.add_argument("--method", default="", help="OCP method (default: pd_ocp_node's)")
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        return run(args)
    except DemoError as exc:
        print(f"pd_demo: FAILED: {exc}", file=sys.stderr, flush=True)
        return 1
    except KeyboardInterrupt:
        print("pd_demo: interrupted", file=sys.stderr)
        return 130


def run(args: argparse.Namespace) -> int:
    import rclpy
    from rclpy.context import Context

    from pd_bringup.bag import deserialize_all
    from pd_core.env import PoweredDescentEnv

    out = args.out or Path("out") / datetime.now().strftime("demo-%Y%m%d-%H%M%S")
    logs = out / "logs"
    logs.mkdir(parents=True, exist_ok=True)
    bag = out / "bag"
    domain, _lock = claim_domain_id()
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain), "PYTHONUNBUFFERED": "1"}
    mode = "lockstep (FAST)" if args.fast else "real time, 5 Hz"
    print(f"pd_demo: {mode}, seed {args.seed}, ROS_DOMAIN_ID={domain}, output {out}", flush=True)

    def node_argv(pkg: str, params: dict[str, str]) -> list[str]:
        argv = [executable(pkg, pkg), "--ros-args"]
        for k, v in params.items():
            argv += ["-p", f"{k}:={v}"]
        return argv

    children: list[Child] = []
    context = Context()
    flight = None
    t_start = time.monotonic()
    try:
        sim_params = {"lockstep": str(args.fast).lower(), "autostart": "false"}
        pol_params = {"model_path": args.model} if args.model else {}
        for name, argv in [
            ("pd_sim_node", node_argv("pd_sim_node", sim_params)),
            ("pd_policy_node", node_argv("pd_policy_node", pol_params)),
            ("pd_ocp_node", node_argv("pd_ocp_node", {})),
            (
                "pd_record",
                [
                    executable("pd_bringup", "pd_record"),
                    "-o",
                    str(bag),
                    "/lander/state",
                    "/lander/thrust_cmd",
                    "/lander/episode",
                ],
            ),
        ]:
            children.append(Child(name, argv, logs, env))
        rclpy.init(context=context, domain_id=domain)
        flight = Flight(context)
        n = flight.node
        ready = flight.spin_until(
            lambda: (
                flight.reset_cli.service_is_ready()
                and flight.ocp_cli.service_is_ready()
                and n.count_publishers("/lander/thrust_cmd") >= 1  # policy loaded its model
                and n.count_subscribers("/lander/state") >= 3  # policy, recorder, us
                and n.count_subscribers("/lander/thrust_cmd") >= 3
            ),  # sim, recorder, us
            START_TIMEOUT_S,
            children,
        )
        if not ready:
            tails = "\n".join(f"  {c.name}:\n{c.tail(5)}" for c in children)
            raise DemoError(f"the stack did not come up within {START_TIMEOUT_S:g} s\n{tails}")
        flight.spin_until(lambda: False, 0.5)  # let discovery settle both ways
        print(f"pd_demo: 4 processes up after {time.monotonic() - t_start:.1f} s", flush=True)

        # The episode's initial state, sampled exactly as pd_sim_node will (same seed, same env).
        _, info = PoweredDescentEnv().reset(seed=args.seed)
        s0 = info["state"]
        print(
            f"  initial state: x = {_fmt(s0[0:3])} m, v = {_fmt(s0[3:6])} m/s, m = {s0[6]:.1f} kg"
        )

        req = flight.ComputeTrajectory.Request(mass=float(s0[6]), method=args.method)
        req.position.x, req.position.y, req.position.z = (float(v) for v in s0[0:3])
        req.velocity.x, req.velocity.y, req.velocity.z = (float(v) for v in s0[3:6])
        ocp = flight.call(flight.ocp_cli, req, 120.0)
        if ocp.success:
            print(
                f"  OCP: {ocp.message}; time of flight {ocp.time_of_flight:.1f} s, fuel "
                f"{ocp.fuel:.1f} kg, solved in {ocp.solve_time:.2f} s; final |x| "
                f"{np.linalg.norm(_vec(ocp.positions[-1])):.3g} m, |v| "
                f"{np.linalg.norm(_vec(ocp.velocities[-1])):.3g} m/s",
                flush=True,
            )
        else:
            print(f"  OCP: no trajectory ({ocp.message}); flying anyway", flush=True)

        reset = flight.ResetEpisode.Request(use_initial_state=False, seed=args.seed)
        resp = flight.call(flight.reset_cli, reset, 10.0)
        if not resp.success:
            raise DemoError(f"/sim/reset refused: {resp.message}")
        got = np.array([*_vec(resp.position), *_vec(resp.velocity), resp.mass])
        if not np.array_equal(got, s0):
            raise DemoError(f"simulator started from {got}, expected {s0}")
        episode = resp.episode
        print(f"  episode {episode} flying ({mode}) ...", flush=True)
        t_fly = time.monotonic()
        budget = 60.0 if args.fast else MAX_EPISODE_TIME_S + 30.0
        if not flight.spin_until(
            lambda: any(r.episode == episode for r in flight.results), budget, children
        ):
            raise DemoError(f"episode {episode} did not end within {budget:g} s")
        result = next(r for r in flight.results if r.episode == episode)
        flight.spin_until(
            lambda: sum(s.episode == episode for s in flight.states) > result.steps, 5.0
        )
        wall = time.monotonic() - t_fly
    finally:
        # Recorder first (closes the bag), then the nodes; all of them, whatever happened.
        for c in sorted(children, key=lambda c: c.name != "pd_record"):
            c.stop()
        if flight is not None:
            flight.close()
        context.try_shutdown()

    # ------------------------------------------------------------------ report
    pos, vel = _vec(result.final_position), _vec(result.final_velocity)
    print(
        f"\nTouchdown after {result.time_of_flight:.1f} s simulated ({result.steps} steps, "
        f"{wall:.1f} s wall clock):"
    )
    print(
        f"  position {_fmt(pos, 3)} m   |x| = {np.linalg.norm(pos):.3f} m "
        f"(landing needs < {REWARD.x_lim_m:g} m)"
    )
    print(
        f"  velocity {_fmt(vel, 3)} m/s |v| = {np.linalg.norm(vel):.3f} m/s "
        f"(landing needs < {REWARD.v_lim_mps:g} m/s)"
    )
    print(f"  mass     {result.final_mass:.1f} kg")
    if ocp.success:
        print(
            f"  fuel     {result.fuel:.1f} kg  vs OCP {ocp.fuel:.1f} kg "
            f"({100.0 * (result.fuel / ocp.fuel - 1.0):+.1f} %)"
        )
    else:
        print(f"  fuel     {result.fuel:.1f} kg  (no OCP reference)")
    print(f"  LANDED: {'yes' if result.landed else 'no'} -- {result.reason}")
    print(f"  commands: rejected {result.rejected_commands}, missed {result.missed_commands}")

    recorded = deserialize_all(bag)
    counts = {t: len(m) for t, m in recorded.items()}
    print(f"  bag {bag}: " + ", ".join(f"{t} {n}" for t, n in counts.items()))

    states = [s for s in flight.states if s.episode == episode]
    by_step = {s.step: s for s in states}
    traj = np.array(
        [
            [*_vec(by_step[k].position), *_vec(by_step[k].velocity), by_step[k].mass]
            for k in sorted(by_step)
        ]
    )
    cmds = {c.step: c for c in flight.commands if c.episode == episode}
    thrust = np.array(
        [_vec(cmds[k].thrust) if k in cmds else [math.nan] * 3 for k in range(result.steps)]
    )
    png = plot(
        out / "flight.png",
        traj,
        thrust.reshape(-1, 3),
        ocp,
        f"seed {args.seed}, {mode}: {'landed' if result.landed else 'not landed'}, fuel "
        f"{result.fuel:.1f} kg (OCP {ocp.fuel:.1f} kg)",
    )
    print(f"  plot {png}")
    print("pd_demo: done, every process stopped", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
