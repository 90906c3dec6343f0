"""pd_sim_node: flies `pd_core.sim.Simulator` and speaks lander/state, lander/thrust_cmd,
lander/episode and sim/reset (relative names: /lander/... in the root namespace).

Real-time mode (default): a wall-clock ticker (absolute deadlines, no drift) advances one step of
dt = 0.2 s and publishes the new state every 1 / rate_hz seconds. The command that answers the
current step must arrive before the next tick; otherwise the step is flown with the last applied
command held, or with zero thrust (`missing_command`). An episode started at start-up or by
sim/reset waits for the first command answering its step 0 before its clock starts (the state is
published again every `resend_s` meanwhile), so a policy that is still loading never misses the
first steps (`start_wait_s` can bound the wait: then it flies without one, with a warning).

Lockstep mode: the simulator advances as soon as a valid command answering the current step has
arrived, so an episode flies as fast as the policy answers and is deterministic. If no answer
comes within `resend_s`, the current state is published again (a restarted policy node then picks
the loop up). With `auto_restart`, the next episode starts as soon as one ends.

The first valid command for a step is flown; later ones for the same step are rejected, counted
and logged like every invalid command. Every parameter is read at start-up (read-only
afterwards); defaults are in pd_bringup/config/sim.yaml.

A managed (lifecycle) node: configure makes the simulator and, with `start_episode`, its first
episode; activate publishes its state and starts flying; deactivate holds the episode at its step
(no state, no step; commands that arrive are kept) and activate goes on from that step, so
nothing is lost or flown twice; sim/reset is refused unless active; cleanup drops the simulator.
`autostart` (default true) configures and activates it at start-up.

Identity: each run has a `lander_id` (the parameter, or a random one at start-up), carried by
every lander/state and echoed by the command answering it. A command for another lander (a
second stack on the same names, without a namespace) is counted as foreign, never flown, and the
first one of each other lander is logged as an error naming it; /diagnostics is then at ERROR.
A sim/reset naming another lander is refused (after `REFUSE_DELAY_S`, so the named lander's
answer reaches the client first), and one naming none is refused while another lander is heard.

For viewers: lander/odom (nav_msgs/Odometry, frame landing_site, child frame lander) with every
state, lander/path (nav_msgs/Path of the episode so far) every `path_period_s` and when the
episode ends, and in lockstep /clock (rosgraph_msgs/Clock): a simulation clock that advances
0.2 s per step and keeps running across episodes (one step between two episodes), so nodes with
use_sim_time follow the flight. In lockstep the odometry and path are stamped on that clock; in
real time on the node's clock. /diagnostics (1 Hz): achieved rate, missed, rejected, lost and
foreign commands (levels: pd_ros_common.diagnostics).
"""

from __future__ import annotations

import re
import secrets
import sys
import threading
import time
from typing import Any

import numpy as np
from nav_msgs.msg import Odometry, Path
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.task import Future
from rosgraph_msgs.msg import Clock

from pd_core.config import DT_S, MAX_EPISODE_TIME_S
from pd_core.sim import (
    MAX_NAV_SIGMA,
    MAX_SIM_DELAY_STEPS,
    MISSING_COMMAND_MODES,
    THRUST_SCALE_RANGE,
    Simulator,
)
from pd_core.ticker import FixedRateTicker, percentiles_ms
from pd_interfaces.msg import EpisodeResult, LanderState, ThrustCommand
from pd_interfaces.srv import ResetEpisode
from pd_ros_common import diagnostics, names, params, qos
from pd_ros_common.convert import (
    clock_msg,
    command_from_msg,
    odometry_msg,
    path_msg,
    pose_stamped,
    result_msg,
    ros_time,
    state_msg,
    state_vector,
    vec3,
)
from pd_ros_common.diagnostics import ERROR, WARN
from pd_ros_common.gaps import SequenceGaps
from pd_ros_common.lifecycle import AUTOSTART, ManagedNode
from pd_ros_common.run import run_node
from pd_ros_common.sources import PublisherNames

NODE_NAME = "pd_sim_node"
AMBIGUOUS_S = 5.0  # a reset naming no lander is refused this long after a foreign command
REFUSE_DELAY_S = 1.0  # a reset for another lander is refused this much later
DT_NS = round(DT_S * 1e9)  # one step of the simulation clock

# name: (default, description); every one is read at start-up.
PARAMETERS: dict[str, tuple[Any, str]] = {
    "rate_hz": (
        1.0 / DT_S,
        "Real-time mode: steps (and lander/state messages) per second of wall clock. "
        "5.0 = real time (one dt = 0.2 s per message). Ignored in lockstep.",
    ),
    "lockstep": (
        False,
        "Step only when the command answering the current step has arrived (as fast as the "
        "policy answers, deterministic) instead of on the wall clock.",
    ),
    "resend_s": (
        1.0,
        "Publish the current state again after this many seconds without an answer: in "
        "lockstep, and in real time while an episode waits for its first command (0 = never).",
    ),
    "start_wait_s": (
        -1.0,
        "Real time: an episode started at start-up or by sim/reset starts its clock when the "
        "first command answering step 0 arrives: -1 = however long that takes, > 0 = at most "
        "this many seconds (then it flies without commands, with a warning), 0 = at once.",
    ),
    "missing_command": (
        "hold",
        "What a step without a fresh valid command flies: 'hold' (the last applied command of "
        "the episode; zero thrust before the first) or 'zero' (zero thrust).",
    ),
    "seed": (
        0,
        "Seed of the first episode (initial state and disturbance); later episodes continue "
        "the RNG unless sim/reset reseeds. -1 = unseeded.",
    ),
    "disturbance": (True, "Apply the random disturbance force of Sec. 3.2 (sigma 100 N)."),
    "autostart": (
        AUTOSTART[0],
        AUTOSTART[1] + " Deprecated old meaning, for this release only: given as false "
        "without start_episode, it is read as start_episode:=false (and the node starts "
        "active), with a warning.",
    ),
    "start_episode": (
        True,
        "Start the first episode when the node is configured (from initial_state, or Table 3 "
        "with seed); it flies once the node is active. false = wait for sim/reset. (Called "
        "autostart before the nodes were managed.)",
    ),
    "auto_restart": (
        False,
        "When an episode ends, start the next one (Table 3, RNG continued): one period later "
        "in real time, at once in lockstep; false = publish the result and wait for sim/reset.",
    ),
    "initial_state": (
        [0.0],
        "[x, y, z, vx, vy, vz, m] (m, m/s, kg) of the first episode (start_episode); any "
        "other length (default [0.0]) = sample Table 3.",
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
    "delay_steps": (
        0,
        "Actuation delay for latency tests: the lander flies the command of this many steps "
        "(0.2 s each) earlier, zero thrust before the first (as pd-eval's delay_steps "
        "dispersion). 0 = none.",
    ),
    "nav_position_sigma_m": (
        0.0,
        "Navigation noise for filter tests: white Gaussian noise (m, per axis, drawn each step) "
        "on the published position, as pd-eval's nav_position_sigma_m dispersion. The episode "
        "result keeps the true state. 0 = none.",
    ),
    "nav_velocity_sigma_mps": (
        0.0,
        "As nav_position_sigma_m, on the published velocity (m/s). 0 = none.",
    ),
    "thrust_scale": (
        1.0,
        "Engine out of spec, for thrust-error tests: every thruster delivers this fraction of "
        "the commanded thrust (0.85 = 15 % short), as a fixed pd-eval thrust_error. 1 = none.",
    ),
    "command_source": (
        "",
        "Name of the one node whose thrust commands fly (e.g. pd_policy_node): commands from "
        "any other publisher, or one the ROS graph cannot name yet, are rejected as foreign and "
        "counted, even when they answer a step first. Empty = any publisher (first command "
        "wins).",
    ),
    "lander_id": (
        "",
        "Identity of this simulator run, carried by every lander/state and echoed by the "
        "commands answering it; commands for another id are counted as foreign and never "
        "flown. Empty = a random 8-hex-digit id at start-up.",
    ),
    "path_period_s": (
        1.0,
        "Publish lander/path (nav_msgs/Path of the episode so far) every this many seconds "
        "of wall clock while flying; it is always published when an episode ends. 0 = only then.",
    ),
}

CHECKS: dict[str, params.Check] = {
    "rate_hz": params.above(0.0),
    "resend_s": params.at_least(0.0),
    "start_wait_s": lambda v: None if v == -1 or v >= 0 else "must be -1 (no limit) or >= 0",
    "missing_command": params.one_of(MISSING_COMMAND_MODES),
    "seed": params.at_least(-1),
    "max_time_s": params.at_least(DT_S),
    "tick_priority": params.at_least(0),
    "delay_steps": lambda v: (
        None if 0 <= v <= MAX_SIM_DELAY_STEPS else f"must be in [0, {MAX_SIM_DELAY_STEPS}]"
    ),
    "log_rejections": params.at_least(0),
    "nav_position_sigma_m": lambda v: (
        None if 0.0 <= v <= MAX_NAV_SIGMA[0] else f"must be in [0, {MAX_NAV_SIGMA[0]:g}]"
    ),
    "nav_velocity_sigma_mps": lambda v: (
        None if 0.0 <= v <= MAX_NAV_SIGMA[1] else f"must be in [0, {MAX_NAV_SIGMA[1]:g}]"
    ),
    "thrust_scale": lambda v: (
        None
        if THRUST_SCALE_RANGE[0] <= v <= THRUST_SCALE_RANGE[1]
        else f"must be in [{THRUST_SCALE_RANGE[0]:g}, {THRUST_SCALE_RANGE[1]:g}]"
    ),
    "command_source": lambda v: (
        None
        if re.fullmatch(r"([A-Za-z_][A-Za-z0-9_]*)?", v)
        else "must be a node name (letters, digits, underscores) or empty"
    ),
    "lander_id": lambda v: (
        None
        if re.fullmatch(r"[A-Za-z0-9_.-]{0,64}", v)
        else "must be at most 64 letters, digits, '_', '.' or '-' (empty = random)"
    ),
    "path_period_s": params.at_least(0.0),
}


class SimNode(ManagedNode):
    """Thin ROS adapter: messages in, `Simulator` calls, messages out. configure makes the
    simulator (and its first episode), activate flies it; inactive, it holds its step."""

    def __init__(self, **kwargs: Any) -> None:
        # Before Node.__init__: destroy_node must work whatever fails after this point.
        self._lock = threading.Lock()
        self._ticker: FixedRateTicker | None = None
        self._sim: Simulator | None = None
        super().__init__(NODE_NAME, **kwargs)
        p = self._p = params.declare(self, PARAMETERS, CHECKS)
        self.autostart = p["autostart"]
        self.start_episode = p["start_episode"]
        given = self._parameter_overrides
        if "autostart" in given and "start_episode" not in given and not p["autostart"]:
            self.get_logger().warning(
                "autostart:=false is read in its old meaning, start_episode:=false (deprecated, "
                "for this release only): autostart now names the lifecycle; set "
                "start_episode:=false to wait for sim/reset, and give start_episode with "
                "autostart:=false for a node that waits unconfigured"
            )
            self.autostart, self.start_episode = True, False
        self.rate_hz = p["rate_hz"]
        self.lockstep = p["lockstep"]
        self.resend_s = p["resend_s"]
        self.start_wait_s = 0.0 if self.lockstep else p["start_wait_s"]
        self.auto_restart = p["auto_restart"]
        self.log_rejections = p["log_rejections"]
        self.tick_priority = p["tick_priority"]
        self.lander_id = p["lander_id"] or secrets.token_hex(4)
        self._nav_sigma = (p["nav_position_sigma_m"], p["nav_velocity_sigma_mps"])
        self._resume_ticker = False  # a ticker was (or would be) running when not active
        # Resets in a group of their own and the refusal delay's timer in another: a reset
        # waiting out REFUSE_DELAY_S (a coroutine) must not hold the group of the commands.
        self._sleep_group = ReentrantCallbackGroup()
        self.create_service(
            ResetEpisode,
            names.RESET_SERVICE,
            self._on_reset,
            qos_profile=qos.SERVICE_QOS,
            callback_group=MutuallyExclusiveCallbackGroup(),
        )
        self._foreign_at = -float("inf")  # monotonic time of the last foreign command
        self._since = diagnostics.Since()
        self._diag_at = time.monotonic()
        self._diag_flying = False
        self.diagnostics = diagnostics.Diagnostics(
            self, "simulator", self.managed_report(self._report), hardware_id=self.lander_id
        )

    def _configure(self) -> str:
        p = self._p
        self._sim = Simulator(
            disturbance=p["disturbance"],
            missing_command=p["missing_command"],
            max_time_s=p["max_time_s"],
            seed=p["seed"] if p["seed"] >= 0 else None,
            command_source=p["command_source"],
            delay_steps=p["delay_steps"],
            nav_sigma=(p["nav_position_sigma_m"], p["nav_velocity_sigma_mps"]),
            thrust_scale=p["thrust_scale"],
            lander_id=self.lander_id,
        )
        self._restart_due = False
        self._resume_ticker = False
        self._waiting_since: float | None = None  # real time: episode waits for its 1st command
        self._last_publish = time.monotonic()
        self._lateness: list[float] = []
        self.lost_commands = 0  # never arrived: sequence gaps plus DDS message-lost events
        self._gaps = SequenceGaps()
        self._sources = PublisherNames(
            lambda: self.get_publishers_info_by_topic(self._cmd_sub.topic_name)
        )
        self._clock_ns = 0  # simulation clock: dt per step, across episodes (integer ns)
        self._path: list[Any] = []  # PoseStamped of the episode so far
        self._path_key: tuple[int, int] = (0, -1)  # (episode, step) of the last pose
        self._path_sent = 0  # poses in the last lander/path published
        self._unpublished = False  # a state made while not active: published on activate

        pub, own = self.create_lifecycle_publisher, self.own
        self._state_pub = own(pub(LanderState, names.STATE_TOPIC, qos.LOOP_PUB_QOS))
        self._episode_pub = own(pub(EpisodeResult, names.EPISODE_TOPIC, qos.EPISODE_QOS))
        self._cmd_sub = own(
            self.create_subscription(
                ThrustCommand,
                names.COMMAND_TOPIC,
                self._on_command,
                qos.LOOP_SUB_QOS,
                event_callbacks=SubscriptionEventCallbacks(message_lost=self._on_lost),
            )
        )
        self._odom_pub = own(pub(Odometry, names.ODOM_TOPIC, qos.LOOP_PUB_QOS))
        self._path_pub = own(pub(Path, names.PATH_TOPIC, qos.PATH_QOS))
        self._clock_pub = (
            own(pub(Clock, names.CLOCK_TOPIC, qos.CLOCK_QOS)) if self.lockstep else None
        )
        if p["path_period_s"] > 0:
            own(self.create_timer(p["path_period_s"], self._path_timer))
        self._links = (-1, -1)
        own(self.create_timer(0.1, self._log_links))
        own(self.create_timer(min(self.resend_s or 0.5, 0.5) / 2, self._resend_check))
        if self.start_episode:
            init = p["initial_state"]
            state = np.asarray(init, dtype=float) if len(init) == 7 else None
            with self._lock:
                self._start_episode(state, None, wait=True)

        mode = "lockstep" if self.lockstep else f"real time at {self.rate_hz:g} Hz"
        return (
            f"simulator ready: {mode}, missing_command={p['missing_command']}, "
            f"disturbance={p['disturbance']}, seed={p['seed']}, "
            f"command_source={p['command_source'] or '(any publisher)'}, "
            f"lander_id={self.lander_id}"
        )

    def _where(self) -> str:
        s = self._sim
        if s is None or not s.counters.episodes_started:
            return "no episode yet"
        return f"episode {s.episode} at step {s.step}" + ("" if s.flying else " (ended)")

    def _activate(self) -> str:
        with self._lock:
            s = self._sim
            self._last_publish = time.monotonic()  # an answer in flight has resend_s to land
            if self._unpublished:
                self._unpublished = False
                self._publish_state()
            if s.flying and self._waiting_since is not None:
                if s.has_fresh_command:  # the first command came while the node was inactive
                    self._start_ticker()
                else:
                    self._waiting_since = time.monotonic()
            elif self._resume_ticker:
                self._start_ticker()
            elif self.lockstep and s.flying and s.has_fresh_command:
                self._advance()  # the answer came while the node was inactive
            return f"flying, {self._where()}" if s.flying else f"{self._where()}; idle"

    def _deactivate(self) -> str:
        with self._lock:
            running = self._ticker is not None or self._resume_ticker
            self._stop_ticker()
            self._resume_ticker = running
            return f"{self._where()} held"

    def _release(self) -> str:
        with self._lock:
            self._stop_ticker()
            s, self._sim = self._sim, None
        if s is None:
            return "nothing held"
        dropped = f"; {self._where_of(s)} dropped" if s.flying else ""
        return f"simulator released after {s.counters.episodes_started} episode(s){dropped}"

    @staticmethod
    def _where_of(s: Simulator) -> str:
        return f"episode {s.episode} at step {s.step}"

    def _log_links(self) -> None:
        """Log when a policy (or monitor) joins or leaves: the matched DDS endpoints change."""
        links = (self._state_pub.get_subscription_count(), self._cmd_sub.get_publisher_count())
        if links != self._links:
            self._links = links
            self.get_logger().info(
                f"links: {links[0]} subscriber(s) of {self._state_pub.topic_name}, "
                f"{links[1]} publisher(s) of {self._cmd_sub.topic_name}"
            )

    def _on_lost(self, info: Any) -> None:
        """Commands DDS reports lost before they reached us: count and log."""
        self._count_lost(int(info.total_count_change), "reported lost by DDS")

    def _count_lost(self, n: int, how: str) -> None:
        self.lost_commands += n
        self.get_logger().warning(f"{n} command(s) {how} [{self.lost_commands} lost so far]")

    # ------------------------------------------------------------------ episodes
    def _start_episode(self, initial_state: np.ndarray | None, seed: int | None, wait: bool) -> int:
        """Reset the simulator and publish step 0 (caller holds the lock). ValueError passes.

        Real time: the clock starts now, or (`wait` and start_wait_s != 0) when the first
        command answering step 0 arrives.
        """
        episode, init, interrupted = self._sim.reset(initial_state, seed)
        if interrupted is not None:
            self._publish_result(interrupted)
        if self._sim.counters.episodes_started > 1:
            self._clock_ns += DT_NS  # the clock keeps running: one step between two episodes
        self._path = []
        self._path_sent = 0
        self._restart_due = False
        self.get_logger().info(
            f"episode {episode} starts at x = {np.round(init[0:3], 2).tolist()} m, "
            f"v = {np.round(init[3:6], 2).tolist()} m/s, m = {init[6]:.1f} kg"
        )
        self._publish_state()
        self._stop_ticker()
        self._waiting_since = None
        if not self.lockstep:
            if wait and self.start_wait_s != 0:
                self._waiting_since = time.monotonic()
            else:
                self._start_ticker()
        return episode

    def _stop_ticker(self) -> None:
        self._resume_ticker = False
        if self._ticker is not None:
            self._keep_lateness(self._ticker)
            self._ticker.stop(join=False)  # it may be waiting for our lock: do not join
            self._ticker = None

    def _start_ticker(self) -> None:
        """A fresh ticker per episode, so every step of it lasts one full period (not while
        the node is inactive: activate starts it)."""
        self._stop_ticker()
        self._waiting_since = None
        if not self.active:
            self._resume_ticker = True
            return
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
                    self._start_episode(None, None, wait=False)  # replaces this ticker
                else:
                    ticker.stop(join=False)
            except Exception as exc:  # never let the clock thread die silently
                self.get_logger().error(f"simulation step failed: {exc!r}")

    def _advance(self) -> None:
        """One step with whatever command the simulator holds; publish state and result."""
        out = self._sim.advance()
        self._clock_ns += DT_NS
        self._publish_state()
        if not out.done:
            return
        self._publish_result(out.result)
        self._restart_due = self.auto_restart
        if self.lockstep and self.auto_restart:
            self._start_episode(None, None, wait=False)
        elif not self._restart_due:
            self._stop_ticker()

    def _publish_state(self) -> None:
        if not self.active:  # the first episode, made by configure: published on activate
            self._unpublished = True
            return
        s = self._sim
        observed = s.observed_state
        self._state_pub.publish(
            state_msg(s.episode, s.step, s.time_s, observed, s.status, self.lander_id)
        )
        self._last_publish = time.monotonic()
        stamp = self._stamp()
        if self._clock_pub is not None:
            self._clock_pub.publish(clock_msg(self._clock_ns))
        self._odom_pub.publish(odometry_msg(observed, stamp, self._nav_sigma))
        if (s.episode, s.step) != self._path_key:  # not again for a resend
            self._path_key = (s.episode, s.step)
            self._path.append(pose_stamped(observed[0:3], stamp))

    def _stamp(self) -> Any:
        """Stamp of the viewer messages: the simulation clock in lockstep, else the node's."""
        if self.lockstep:
            return ros_time(self._clock_ns)
        return self.get_clock().now().to_msg()

    def _publish_path(self) -> None:
        """lander/path of the episode so far (caller holds the lock)."""
        if self._path:
            self._path_pub.publish(path_msg(self._path, self._path[-1].header.stamp))
            self._path_sent = len(self._path)

    def _path_timer(self) -> None:
        with self._lock:
            if self.active and self._sim.flying and len(self._path) != self._path_sent:
                self._publish_path()

    def _publish_result(self, result: dict[str, Any]) -> None:
        self._publish_path()
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
            f"missed {result['missed_commands']}, foreign {result['foreign_commands']} "
            f"(totals: accepted {c.accepted_commands}, rejected {c.rejected_commands}, missed "
            f"{c.missed_commands}, lost {self.lost_commands}, foreign {c.foreign_commands})"
            f"{jitter}"
        )

    # ------------------------------------------------------------------ callbacks
    def _on_command(self, msg: ThrustCommand, info: Any) -> None:
        missing, first, last = self._gaps.update(info)
        if missing:  # a sender's queue overflowed: those commands never reached us
            self._count_lost(missing, f"of one publisher never arrived (sequence {first}..{last})")
        source = self._sources.name_of(info) if self._sim.command_source else ""
        cmd = command_from_msg(msg, source)
        with self._lock:
            if self._sim is None:
                return
            known = cmd.lander_id in self._sim.counters.foreign_by_lander
            err = self._sim.submit(cmd)
            if (
                err is not None
                and err[0] == "foreign"
                and cmd.lander_id not in ("", self.lander_id)
            ):
                self._foreign_at = time.monotonic()
                if not known:  # once per other lander: it is a set-up error, not a command's
                    self.get_logger().error(
                        f"commands for lander {cmd.lander_id!r} arrive on "
                        f"{self._cmd_sub.topic_name}; this is lander {self.lander_id!r}: a second "
                        "stack shares these names (give each its own namespace, -r "
                        "__ns:=/vehicle2). Its commands are counted as foreign, never flown"
                    )
                return
            if err is not None:
                n = self._sim.counters.rejected_commands
                if n <= self.log_rejections or n % 100 == 0:
                    self.get_logger().warning(
                        f"command rejected ({err[0]}): {err[1]} [{n} rejected so far]"
                    )
                return
            if not self.active:
                return  # held: activate flies it
            if self.lockstep and self._sim.has_fresh_command:
                self._advance()
            elif self._waiting_since is not None and self._sim.has_fresh_command:
                waited = time.monotonic() - self._waiting_since
                self.get_logger().info(
                    f"first command of episode {self._sim.episode} after {waited:.1f} s: "
                    "the clock starts"
                )
                self._start_ticker()

    def _resend_check(self) -> None:
        with self._lock:
            if (
                not self.active
                or not self._sim.flying
                or (not self.lockstep and self._waiting_since is None)
            ):
                return
            now = time.monotonic()
            waited = now - self._waiting_since if self._waiting_since is not None else 0.0
            if self.start_wait_s > 0 and waited > self.start_wait_s:
                self.get_logger().warning(
                    f"no command for step 0 of episode {self._sim.episode} within "
                    f"{self.start_wait_s:g} s: flying without (missing_command applies)"
                )
                self._start_ticker()
            elif self.resend_s > 0 and now - self._last_publish >= self.resend_s:
                if self.lockstep:
                    self.get_logger().info(
                        f"lockstep: no answer for step {self._sim.step} after "
                        f"{self.resend_s:g} s; publishing the state again"
                    )
                self._publish_state()

    async def _on_reset(
        self, request: ResetEpisode.Request, response: ResetEpisode.Response
    ) -> ResetEpisode.Response:
        response.lander_id = self.lander_id
        why = None
        if not self.active:
            why = f"reset refused: {self.refusal()}"
        elif request.lander_id and request.lander_id != self.lander_id:
            why = (
                f"reset refused: it is for lander {request.lander_id!r}, this is {self.lander_id!r}"
            )
            await self._sleep(REFUSE_DELAY_S)  # the named lander answers first
        elif not request.lander_id and time.monotonic() - self._foreign_at < AMBIGUOUS_S:
            with self._lock:
                others = ", ".join(sorted(self._sim.counters.foreign_by_lander))
            why = (
                f"reset refused: ambiguous, lander {self.lander_id!r} shares its names with "
                f"{others}; name the lander (ResetEpisode.lander_id)"
            )
        if why is not None:
            response.success = False
            response.message = why
            response.episode = self._sim.episode if self._sim is not None else 0
            self.get_logger().warning(why)
            return response
        state = None
        if request.use_initial_state:
            state = state_vector(request.position, request.velocity, request.mass)
        seed = int(request.seed) if request.seed >= 0 else None
        with self._lock:
            try:
                episode = self._start_episode(state, seed, wait=True)
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

    async def _sleep(self, seconds: float) -> None:
        """Wait without blocking the executor (a one-shot timer completes a future)."""
        done: Future = Future()

        def fire() -> None:
            timer.cancel()
            if not done.done():
                done.set_result(None)

        timer = self.create_timer(seconds, fire, callback_group=self._sleep_group)
        try:
            await done
        finally:
            self.destroy_timer(timer)

    def _report(self) -> diagnostics.Report:
        """/diagnostics of the last period (rules: pd_ros_common.diagnostics)."""
        now = time.monotonic()
        with self._lock:
            s, c = self._sim, self._sim.counters
            flying = s.flying
            d = self._since(
                steps=c.steps,
                missed=c.missed_commands,
                rejected=c.rejected_commands,
                foreign=c.foreign_commands,
                lost=self.lost_commands,
            )
            others = sorted(c.foreign_by_lander)
            by_reason = dict(c.rejected_by_reason)
            episode, step = s.episode, s.step
            totals = (c.steps, c.accepted_commands, c.missed_commands, c.rejected_commands)
            foreign_total = c.foreign_commands
        period = now - self._diag_at
        rate = d["steps"] / period if period > 0 else 0.0
        whole_period = flying and self._diag_flying and not self.lockstep
        self._diag_at, self._diag_flying = now, flying
        r = diagnostics.Report(ok_message="flying" if flying else "idle")
        r.values = {
            "lander_id": self.lander_id,
            "mode": "lockstep" if self.lockstep else "real time",
            "rate_hz (target)": self.rate_hz if not self.lockstep else 0.0,
            "achieved rate (steps/s)": rate,
            "episode": episode,
            "step": step,
            "flying": flying,
            "steps": totals[0],
            "accepted commands": totals[1],
            "missed commands": totals[2],
            "missed (last period)": int(d["missed"]),
            "rejected commands": totals[3],
            "rejected (last period)": int(d["rejected"]),
            "rejected by reason": ", ".join(f"{k} {v}" for k, v in sorted(by_reason.items()))
            or "none",
            "lost commands": self.lost_commands,
            "foreign commands": foreign_total,
            "foreign (last period)": int(d["foreign"]),
            "other landers": others or "none",
            **diagnostics.readers(
                self._state_pub, self._episode_pub, self._odom_pub, self._path_pub
            ),
        }
        r.rule(
            ERROR,
            d["foreign"] > 0,
            f"{int(d['foreign'])} command(s) for other lander(s) {', '.join(others)}: a second "
            "stack shares these names",
        )
        r.rule(WARN, d["missed"] > 0, f"{int(d['missed'])} step(s) flown without a command")
        r.rule(WARN, d["rejected"] > 0, f"{int(d['rejected'])} command(s) rejected")
        r.rule(WARN, d["lost"] > 0, f"{int(d['lost'])} command(s) lost")
        r.rule(
            WARN,
            whole_period and rate < diagnostics.RATE_SHORTFALL * self.rate_hz,
            f"achieved {rate:.2f} steps/s of {self.rate_hz:g}",
        )
        return r

    def destroy_node(self) -> None:
        with self._lock:
            ticker, self._ticker = self._ticker, None
        if ticker is not None:
            ticker.stop()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    return run_node(NODE_NAME, __doc__ or "", PARAMETERS, SimNode, args)


if __name__ == "__main__":
    sys.exit(main())
