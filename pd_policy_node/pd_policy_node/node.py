"""pd_policy_node: answers every /lander/state with one /lander/thrust_cmd from a trained policy.

The model is loaded with `pd_core.load_policy` at start-up; a missing or mismatched model stops the
node with a message naming the file and what is wrong (exit status 1). A state with NaN, infinite
or absurd values is logged and gets no command; a state whose status is not FLYING (the final
state of an episode) needs no command and gets none.

Parameters (read at start-up; defaults in pd_bringup/config/policy.yaml):
  model_path      policy file (.pt with its .json beside it); "" = the shipped model, see
                  `default_model_path`
  stats_period_s  log decision-time statistics every this many seconds (0 = only at shutdown)
"""

from __future__ import annotations

import os
import sys
import time
from collections import deque
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
from geometry_msgs.msg import Vector3
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

import pd_core
from pd_core.cli.node_help import node_help, wants_help
from pd_core.config import TABLE3
from pd_core.policy import PolicyLoadError
from pd_interfaces.msg import LanderState, ThrustCommand

NODE_NAME = "pd_policy_node"
MODEL_ENV = "PD_MODEL_PATH"
# The shipped policy (models/pd_dqn_best.md says how it was trained and how it scores).
SHIPPED_MODEL = Path("models") / "pd_dqn_best.pt"

# RELIABLE, VOLATILE like pd_sim_node's /lander/state publisher and /lander/thrust_cmd
# subscription (depth is not part of QoS matching). The subscription keeps 100: a burst of
# states (pd_replay, a busy CPU) is queued and answered one by one instead of dropped. The
# command publisher keeps 1000 (more than a 750-step episode), so slower subscribers (recorder,
# monitors) catch up after lockstep bursts: a full KEEP_LAST writer history drops samples that a
# slow reader has not acknowledged yet.
LOOP_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=100,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
CMD_PUB_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1000,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)

PARAMETERS: dict[str, tuple[Any, str]] = {
    "model_path": (
        "",
        "Policy file (<name>.pt with <name>.json beside it). Empty = the shipped model: "
        f"${MODEL_ENV} if set, else $PD_ROOT/{SHIPPED_MODEL} (PD_ROOT is set by env.sh), else "
        f"share/pd_policy_node/{SHIPPED_MODEL} of an install, else {SHIPPED_MODEL} in the "
        "source tree the package runs from.",
    ),
    "stats_period_s": (
        10.0,
        "Log decision-time statistics (p50/p99/max of the state->command callback) every this "
        "many seconds; 0 = only at shutdown.",
    ),
}


def default_model_path() -> Path:
    """The shipped model: first existing candidate, else the first candidate (for the message)."""
    if os.environ.get(MODEL_ENV):
        return Path(os.environ[MODEL_ENV])
    candidates: list[Path] = []
    if os.environ.get("PD_ROOT"):
        candidates.append(Path(os.environ["PD_ROOT"]) / SHIPPED_MODEL)
    for prefix in filter(None, os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)):
        candidates.append(Path(prefix) / "share" / NODE_NAME / SHIPPED_MODEL)
    candidates += [parent / SHIPPED_MODEL for parent in Path(__file__).resolve().parents]
    for c in candidates:
        if c.is_file():
            return c
    return candidates[0]


class PolicyNode(Node):
    """Thin ROS adapter over `pd_core.policy.Policy`."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        for name, (default, text) in PARAMETERS.items():
            self.declare_parameter(
                name, default, ParameterDescriptor(description=text, read_only=True)
            )
        path_param = str(self.get_parameter("model_path").value)
        self.model_path = Path(path_param) if path_param else default_model_path()
        self.policy = pd_core.load_policy(self.model_path)  # PolicyLoadError: main() reports
        # Warm up numpy so the first real state is answered as fast as the rest.
        self.policy.act((TABLE3.lo + TABLE3.hi) / 2)

        self._times: deque[float] = deque(maxlen=100_000)
        self._since_log: list[float] = []
        self.answered = 0
        self.invalid = 0

        # Created after the model loaded: a publisher on /lander/thrust_cmd means "ready".
        self._cmd_pub = self.create_publisher(ThrustCommand, "/lander/thrust_cmd", CMD_PUB_QOS)
        self._state_sub = self.create_subscription(
            LanderState, "/lander/state", self._on_state, LOOP_QOS
        )
        period = float(self.get_parameter("stats_period_s").value)
        if period > 0:
            self.create_timer(period, self._log_stats)
        meta = self.policy.metadata
        self.get_logger().info(
            f"policy ready: {self.model_path} (network {meta['network']['hidden']}, "
            f"{self.policy.actions.n} actions, code {meta.get('code_version', '?')})"
        )
        # DDS discovery of the simulator takes a moment after start-up; say when it is done.
        self._connect_timer = self.create_timer(0.05, self._check_connected)

    def _check_connected(self) -> None:
        n = self._state_sub.get_publisher_count()
        if n > 0:
            self.get_logger().info(f"policy connected: {n} publisher(s) of /lander/state matched")
            self._connect_timer.cancel()

    def _on_state(self, msg: LanderState) -> None:
        t0 = time.perf_counter()
        if msg.status != LanderState.FLYING:
            return  # the episode is over: nothing to answer
        p, v = msg.position, msg.velocity
        state = np.array([p.x, p.y, p.z, v.x, v.y, v.z, msg.mass])
        try:
            action = self.policy.act(state)
        except ValueError as exc:
            self.invalid += 1
            if self.invalid <= 20 or self.invalid % 100 == 0:
                self.get_logger().warning(
                    f"state of episode {msg.episode} step {msg.step} rejected, no command "
                    f"sent: {exc} [{self.invalid} invalid states so far]"
                )
            return
        thrust = self.policy.thrust(action)
        cmd = ThrustCommand(episode=msg.episode, step=msg.step, action=action)
        cmd.header.stamp = msg.header.stamp
        cmd.header.frame_id = msg.header.frame_id
        cmd.thrust = Vector3(x=float(thrust[0]), y=float(thrust[1]), z=float(thrust[2]))
        self._cmd_pub.publish(cmd)
        dt = time.perf_counter() - t0
        self._times.append(dt)
        self._since_log.append(dt)
        self.answered += 1

    def decision_stats(self, samples: Any = None) -> str:
        a = np.asarray(self._times if samples is None else samples, dtype=float) * 1e3
        if a.size == 0:
            return "no states answered yet"
        return (
            f"{a.size} decisions: p50 {np.percentile(a, 50):.3f} ms, "
            f"p99 {np.percentile(a, 99):.3f} ms, max {a.max():.3f} ms"
        )

    def _log_stats(self) -> None:
        if self._since_log:
            self.get_logger().info(
                f"decision time (last period) {self.decision_stats(self._since_log)}; "
                f"{self.answered} answered, {self.invalid} invalid states in all"
            )
            self._since_log = []


def main(args: list[str] | None = None) -> int:
    argv = sys.argv[1:] if args is None else args
    if wants_help(argv):
        print(node_help("pd_policy_node", "pd_policy_node", __doc__ or "", PARAMETERS))
        return 0
    rclpy.init(args=args)
    node = None
    try:
        node = PolicyNode()
        rclpy.spin(node)
    except PolicyLoadError as exc:
        rclpy.logging.get_logger(NODE_NAME).fatal(f"cannot start: {exc}")
        return 1
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            try:
                node.get_logger().info(f"decision time overall: {node.decision_stats()}")
            except Exception:  # logging may already be down at shutdown
                pass
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
