"""pd_sim_node: flies `pd_core.sim.Simulator` and speaks /lander/state, /lander/thrust_cmd,
/lander/episode and /sim/reset.

Real-time mode (default): a wall-clock ticker (absolute deadlines, no drift) advances one step of
dt = 0.2 s and publishes the new state every 1 / rate_hz seconds. The command that answers the
current step must arrive before the next tick; otherwise the step is flown with the last applied
command held, or with zero thrust (`missing_command`).

Lockstep mode: the simulator advances as soon as a valid command answering the current step has
arrived, so an episode flies as fast as the policy answers and is deterministic. If no answer
comes within `lockstep_resend_s`, the current state is published again (a restarted policy node
then picks the loop up).

Every parameter is read at start-up (read-only afterwards); defaults are in
pd_bringup/config/sim.yaml.
"""

from __future__ import annotations

import sys
import threading
import time
from typing import Any

import numpy as np
import rclpy
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from pd_core.cli.node_help import node_help, wants_help
from pd_core.config import DT_S, MAX_EPISODE_TIME_S
from pd_core.sim import MISSING_COMMAND_MODES, FixedRateTicker, Simulator, percentiles_ms
from pd_interfaces.msg import EpisodeResult, LanderState, ThrustCommand
from pd_interfaces.srv import ResetEpisode
from pd_sim_node.convert import command_from_msg, from_vec3, result_msg, state_msg, vec3

NODE_NAME = "pd_sim_node"

# State and commands: every message counts, nobody needs old ones (compatible with any
# RELIABLE or BEST_EFFORT, VOLATILE subscriber). The subscription keeps 10; the state publisher
# keeps 1000 unacknowledged messages (more than a whole 750-step episode), so a slower subscriber
# (recorder, monitor) catches up after a lockstep burst instead of losing states: a KEEP_LAST
# writer drops its oldest sample for every reader once its history is full (depth is not part
# of QoS matching).
LOOP_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
STATE_PUB_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1000,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
# Episode results: a late subscriber (VOLATILE or TRANSIENT_LOCAL) may still want the last ones.
EPISODE_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)

# name: (default, description); every one is read at start-up.
PARAMETERS: dict[str, tuple[Any, str]] = {
    "rate_hz": (
        1.0 / DT_S,
        "Real-time mode: steps (and /lander/state messages) per second of wall clock. "
        "5.0 = real time (one dt = 0.2 s per message). Ignored in lockstep.",
    ),
    "lockstep": (
        False,
        "Step only when the command answering the current step has arrived (as fast as the "
        "policy answers, deterministic) instead of on the wall clock.",
    ),
    "lockstep_resend_s": (
        1.0,
        "Lockstep: publish the current state again after this many seconds without an answer "
        "(0 = never).",
    ),
    "missing_command": (
        "hold",
        "What a step without a fresh valid command flies: 'hold' (the last applied command of "
        "the episode; zero thrust before the first) or 'zero' (zero thrust).",
    ),
    "seed": (
        0,
        "Seed of the first episode (initial state and disturbance); later episodes continue "
        "the RNG unless /sim/reset reseeds. -1 = unseeded.",
    ),
    "disturbance": (True, "Apply the random disturbance force of Sec. 3.2 (sigma 100 N)."),
    "autostart": (
        True,
        "Start the first episode at start-up (from initial_state, or Table 3 with seed). "
        "false = wait for /sim/reset.",
    ),
    "auto_restart": (
        False,
        "When an episode ends, start the next one (Table 3, RNG continued) one period later; "
        "false = publish the result and wait for /sim/reset.",
    ),
    "initial_state": (
        [0.0],
        "[x, y, z, vx, vy, vz, m] (m, m/s, kg) of the autostarted episode; any other length "
        "(default [0.0]) = sample Table 3.",
    ),
    "max_time_s": (
        MAX_EPISODE_TIME_S,
        "Simulation time after which an episode ends OUT_OF_TIME (truncated).",
    ),
    "tick_priority": (
        0,
        "Real-time mode: > 0 runs the clock thread under SCHED_FIFO at this priority (Linux, "
        "needs CAP_SYS_NICE; lowers period jitter on a busy machine); 0 = normal scheduling.",
    ),
    "log_rejections": (
        20,
        "Rejected commands logged one by one per episode; after that every 100th (all are "
        "counted in EpisodeResult.rejected_commands).",
    ),
}


class SimNode(Node):
    """Thin ROS adapter: messages in, `Simulator` calls, messages out."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        for name, (default, text) in PARAMETERS.items():
            self.declare_parameter(
                name, default, ParameterDescriptor(description=text, read_only=True)
            )
        p = {name: self.get_parameter(name).value for name in PARAMETERS}
        if p["missing_command"] not in MISSING_COMMAND_MODES:
            raise ValueError(
                f"missing_command must be one of {MISSING_COMMAND_MODES}, "
                f"got {p['missing_command']!r}"
            )
        if not p["rate_hz"] > 0:
            raise ValueError(f"rate_hz must be > 0, got {p['rate_hz']}")
        self.rate_hz = float(p["rate_hz"])
        self.lockstep = bool(p["lockstep"])
        self.resend_s = float(p["lockstep_resend_s"])
        self.auto_restart = bool(p["auto_restart"])
        self.log_rejections = int(p["log_rejections"])
        self.tick_priority = int(p["tick_priority"])
        seed = int(p["seed"])

        self._lock = threading.Lock()
        self._sim = Simulator(
            disturbance=bool(p["disturbance"]),
            missing_command=str(p["missing_command"]),
            max_time_s=float(p["max_time_s"]),
            seed=seed if seed >= 0 else None,
        )
        self._ticker: FixedRateTicker | None = None
        self._restart_due = False
        self._last_publish = time.monotonic()
        self._lateness: list[float] = []

        self._state_pub = self.create_publisher(LanderState, "/lander/state", STATE_PUB_QOS)
        self._episode_pub = self.create_publisher(EpisodeResult, "/lander/episode", EPISODE_QOS)
        self._cmd_sub = self.create_subscription(
            ThrustCommand, "/lander/thrust_cmd", self._on_command, LOOP_QOS
        )
        self.create_service(ResetEpisode, "/sim/reset", self._on_reset)
        self._links = (-1, -1)
        self.create_timer(0.1, self._log_links)
        if self.lockstep and self.resend_s > 0:
            self.create_timer(min(self.resend_s, 0.5) / 2, self._resend_check)

        mode = "lockstep" if self.lockstep else f"real time at {self.rate_hz:g} Hz"
        self.get_logger().info(
            f"simulator ready: {mode}, missing_command={p['missing_command']}, "
            f"disturbance={p['disturbance']}, seed={seed}"
        )
        if p["autostart"]:
            init = p["initial_state"]
            state = np.asarray(init, dtype=float) if len(init) == 7 else None
            with self._lock:
                self._start_episode(state, None)

    def _log_links(self) -> None:
        """Log when a policy (or monitor) joins or leaves: the matched DDS endpoints change."""
        links = (self._state_pub.get_subscription_count(), self._cmd_sub.get_publisher_count())
        if links != self._links:
            self._links = links
            self.get_logger().info(
                f"links: {links[0]} subscriber(s) of /lander/state, "
                f"{links[1]} publisher(s) of /lander/thrust_cmd"
            )

    # ------------------------------------------------------------------ episodes
    def _start_episode(self, initial_state: np.ndarray | None, seed: int | None) -> int:
        """Reset the simulator and publish step 0 (caller holds the lock). ValueError passes."""
        episode, init, interrupted = self._sim.reset(initial_state, seed)
        if interrupted is not None:
            self._publish_result(interrupted)
        self._restart_due = False
        self.get_logger().info(
            f"episode {episode} starts at x = {np.round(init[0:3], 2).tolist()} m, "
            f"v = {np.round(init[3:6], 2).tolist()} m/s, m = {init[6]:.1f} kg"
        )
        self._publish_state()
        if not self.lockstep:
            self._start_ticker()
        return episode

    def _start_ticker(self) -> None:
        """A fresh ticker per episode, so every step of it lasts one full period."""
        if self._ticker is not None:
            self._keep_lateness(self._ticker)
            self._ticker.stop(join=False)  # it may be waiting for our lock: do not join
        ticker = FixedRateTicker(
            1.0 / self.rate_hz,
            lambda: self._tick(ticker),
            name="sim-tick",
            priority=self.tick_priority,
        )
        self._ticker = ticker
        ticker.start()

    def _keep_lateness(self, ticker: FixedRateTicker) -> None:
        self._lateness.extend(ticker.lateness_s)
        ticker.lateness_s = []
        del self._lateness[:-10000]

    def _tick(self, ticker: FixedRateTicker) -> None:
        with self._lock:
            if ticker.priority_error:
                self.get_logger().warning(ticker.priority_error)
                self.tick_priority = 0
                ticker.priority_error = None
            if ticker is not self._ticker:  # superseded by a reset
                ticker.stop(join=False)
                return
            try:
                if self._sim.flying:
                    self._advance()
                elif self._restart_due:
                    self._start_episode(None, None)  # replaces this ticker
                else:
                    ticker.stop(join=False)
            except Exception as exc:  # never let the clock thread die silently
                self.get_logger().error(f"simulation step failed: {exc!r}")

    def _advance(self) -> None:
        """One step with whatever command the simulator holds; publish state and result."""
        out = self._sim.advance()
        self._publish_state()
        if out.done:
            self._publish_result(out.result)
            self._restart_due = self.auto_restart
            if not self._restart_due and self._ticker is not None:
                self._ticker.stop(join=False)

    def _publish_state(self) -> None:
        s = self._sim
        self._state_pub.publish(state_msg(s.episode, s.step, s.time_s, s.state, s.status))
        self._last_publish = time.monotonic()

    def _publish_result(self, result: dict[str, Any]) -> None:
        self._episode_pub.publish(result_msg(result))
        c = self._sim.counters
        if self._ticker is not None:
            self._keep_lateness(self._ticker)
        jitter = ""
        if self._lateness and not self.lockstep:
            q = percentiles_ms(self._lateness)
            jitter = f"; tick lateness p50 {q['p50']:.3f} ms, p99 {q['p99']:.3f} ms"
        self.get_logger().info(
            f"episode {result['episode']} ended after {result['steps']} steps "
            f"({result['time_of_flight']:.1f} s): {result['reason']}; fuel "
            f"{result['fuel']:.1f} kg; commands rejected {result['rejected_commands']}, "
            f"missed {result['missed_commands']} (totals: accepted {c.accepted_commands}, "
            f"rejected {c.rejected_commands}, missed {c.missed_commands}){jitter}"
        )

    # ------------------------------------------------------------------ callbacks
    def _on_command(self, msg: ThrustCommand) -> None:
        try:
            cmd = command_from_msg(msg)
        except (TypeError, ValueError) as exc:  # cannot happen with typed fields; be safe
            self.get_logger().warning(f"unreadable command rejected: {exc}")
            return
        with self._lock:
            err = self._sim.submit(cmd)
            if err is not None:
                n = self._sim.counters.rejected_commands
                if n <= self.log_rejections or n % 100 == 0:
                    self.get_logger().warning(
                        f"command rejected ({err[0]}): {err[1]} [{n} rejected so far]"
                    )
                return
            if self.lockstep and self._sim.has_fresh_command:
                self._advance()

    def _resend_check(self) -> None:
        with self._lock:
            if self._sim.flying and time.monotonic() - self._last_publish >= self.resend_s:
                self.get_logger().info(
                    f"lockstep: no answer for step {self._sim.step} after {self.resend_s:g} s; "
                    "publishing the state again"
                )
                self._publish_state()

    def _on_reset(
        self, request: ResetEpisode.Request, response: ResetEpisode.Response
    ) -> ResetEpisode.Response:
        state = None
        if request.use_initial_state:
            state = np.array(
                [*from_vec3(request.position), *from_vec3(request.velocity), request.mass]
            )
        seed = int(request.seed) if request.seed >= 0 else None
        with self._lock:
            try:
                episode = self._start_episode(state, seed)
            except ValueError as exc:
                response.success = False
                response.message = f"reset refused: {exc}"
                response.episode = self._sim.episode
                self.get_logger().warning(response.message)
                return response
            init = self._sim.state
        response.success = True
        response.message = f"episode {episode} started"
        response.episode = episode
        response.position = vec3(init[0:3])
        response.velocity = vec3(init[3:6])
        response.mass = float(init[6])
        return response

    def destroy_node(self) -> None:
        with self._lock:
            ticker, self._ticker = self._ticker, None
        if ticker is not None:
            ticker.stop()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    argv = sys.argv[1:] if args is None else args
    if wants_help(argv):
        print(node_help("pd_sim_node", "pd_sim_node", __doc__ or "", PARAMETERS))
        return 0
    rclpy.init(args=args)
    node = None
    try:
        node = SimNode()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except ValueError as exc:  # a bad parameter value
        print(f"{NODE_NAME}: {exc}", file=sys.stderr)
        return 2
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
