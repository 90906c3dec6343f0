"""pd_policy_node: answers every lander/state with one lander/thrust_cmd from a policy, and says
on lander/guidance_status who decided it (one GuidanceStatus per command).

Whatever answers flies through `pd_core.runtime.Runtime`: the network (or controller) behind the
runtime layer the policy file pins, and one `Decision` per step.

The controller is the trained DQN policy (`controller` dqn, the default: the policy file
`model_path`, or the shipped one) or a reference controller of
`pd_core.teachers.registry.make_controller` (zemzev, zemzev-vernier, and the MPC teachers where
pd_core has them), built by `pd_core.runtime.build` as pd-eval and campaigns build it.
A missing or mismatched model, or an unknown controller, stops the node at start-up with one line
naming the file or the name and what is wrong (exit status 1; a bad parameter type is status 2).
A state with NaN, infinite or absurd values is logged and gets no command; a state whose status is
not FLYING (the final state of an episode) needs no command and gets none, and a state sent again
after it was answered (a lockstep resend) is not answered twice. States that never
reach the node (a step gap within an episode, or a DDS message-lost event) are counted and logged.

Every command (and its guidance status) carries the `lander_id` of the state it answers, so a
simulator can tell its own commands from another's. States of a second lander on the same names
(two stacks without namespaces) are still answered, each with its own id and with the runtime's
memory started afresh whenever the lander changes (it never mixes two landers), and the first
state of each further lander is logged as an error naming it; /diagnostics is then at ERROR.
/diagnostics (1 Hz): decision time p50/p99, the runtime layer's share of changed actions per rule
(`Runtime.counts`), the model file and the runtime config's hash (levels:
pd_ros_common.diagnostics).

A managed (lifecycle) node: configure loads the policy (the slow part: torch, the weights, a
warm-up) and makes its topics; activate starts answering; inactive, states are counted and never
answered; cleanup releases the policy with its decision-time summary. `autostart` (default
true) configures and activates it at start-up, where a bad model file stops it in one line.

Parameters are read at start-up; defaults in pd_bringup/config/policy.yaml. 'shield' and
'shield_settings', the old names of 'layer' and 'layer_settings', still work for one release:
set, they warn and are flown; set beside a new name that disagrees, configure refuses them.
"""

from __future__ import annotations

import sys
import time
from collections import deque
from pathlib import Path
from typing import Any

import numpy as np
from rclpy.event_handler import SubscriptionEventCallbacks

from pd_core.config import TABLE3
from pd_core.runtime.build import CONTROLLER, MODEL_ENV, ROOT_ENV, Built, build
from pd_core.runtime.layer import Runtime
from pd_core.runtime.policy_file import LAYER_MODES, SHIPPED_POLICY, PolicyLoadError
from pd_core.state import check_state
from pd_core.teachers.registry import CONTROLLERS
from pd_interfaces.msg import GuidanceStatus, LanderState, ThrustCommand
from pd_ros_common import diagnostics, names, params, qos
from pd_ros_common.convert import command_msg, guidance_msg, state_from_msg
from pd_ros_common.lifecycle import AUTOSTART, ManagedNode
from pd_ros_common.run import run_node

NODE_NAME = names.POLICY_NODE
DQN = "dqn"

PARAMETERS: dict[str, tuple[Any, str]] = {
    "controller": (
        DQN,
        "What answers the states: 'dqn' (the trained policy of model_path) or a reference "
        "controller of pd_core.teachers.registry.make_controller ('zemzev', 'zemzev-vernier', "
        "'mpc-fuel', 'mpc-energy' where pd_core has them).",
    ),
    "model_path": (
        "",
        "Policy file (<name>.pt with <name>.json beside it) of the 'dqn' controller. Empty = "
        f"the shipped model: ${MODEL_ENV} if set, else ${ROOT_ENV}/{SHIPPED_POLICY} ({ROOT_ENV} is "
        f"set by env.sh), else {SHIPPED_POLICY} in the source tree the package runs from.",
    ),
    "layer": (
        "file",
        "Runtime layer (pd_core.runtime: prediction through the actuation delay identified in "
        "flight, navigation filter, handover to ZEM/ZEV-vernier outside the trained envelope, "
        "braking limit, touchdown guard): 'file' as the policy file pins it, 'always' the "
        "code's default config (also around a reference controller), or 'never' (the bare "
        "network; YAML reads on/off as booleans).",
    ),
    "layer_settings": (
        "",
        "Runtime-layer settings changed from what 'layer' gives, as K=V,K=V (fields of "
        "pd_core.runtime.config.RuntimeConfig, e.g. 'nav_filter.enabled=0,touchdown_speed_mps=0' "
        "for an ablation in the closed loop; pd-eval's set:K=V,...:SPEC does the same offline). "
        "Refused at start-up in one line where a setting is bad. Empty = none.",
    ),
    # the old names, for one release: a value other than the default is flown, with a warning
    "shield": ("file", "Deprecated: the old name of 'layer' (it warns)."),
    "shield_settings": ("", "Deprecated: the old name of 'layer_settings' (it warns)."),
    "stats_period_s": (
        10.0,
        "Log decision-time statistics (p50/p99/max of the state->command callback) every this "
        "many seconds; 0 = only at shutdown.",
    ),
    "autostart": AUTOSTART,
}
CHECKS: dict[str, params.Check] = {
    "stats_period_s": params.at_least(0.0),
    "layer": params.one_of(LAYER_MODES),
    "shield": params.one_of(LAYER_MODES),
}
RENAMED = {"shield": "layer", "shield_settings": "layer_settings"}  # deprecated -> new name
LOG_FIRST = 20  # per kind of problem, log this many one by one, then every 100th


def build_policy(name: str, model_path: str, layer: str = "file", settings: str = "") -> Built:
    """What flies for the node's parameters (`pd_core.runtime.build`, always behind a
    `Runtime`): the policy file `model_path` (empty: the shipped one) for 'dqn', else the
    reference controller `name`; PolicyLoadError in one line if it cannot be built."""
    spec: str | Path = f"{CONTROLLER}{name}"
    if name == DQN:
        spec = Path(model_path) if model_path else ""
    try:
        return build(spec, layer=layer, settings=settings, as_runtime=True)
    except PolicyLoadError as exc:
        if name != DQN and name not in CONTROLLERS:  # the registry's refusal, as a parameter
            raise PolicyLoadError(f"controller {name!r}: {exc} (or 'dqn')") from None
        raise


class PolicyNode(ManagedNode):
    """Thin ROS adapter over a `pd_core` policy or controller. configure loads it (and warms
    it up) and makes the topics; inactive, states are heard and counted but never answered."""

    expected_errors = (*ManagedNode.expected_errors, PolicyLoadError)

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self._p = params.declare(self, PARAMETERS, CHECKS)
        self.autostart = self._p["autostart"]
        self.controller_name = self._p["controller"]
        self.model_file = ""  # the policy file flown, once configured ("" for a controller)
        self.policy: Runtime | None = None
        self.ignored = 0  # states heard while not active (never answered)
        self.diagnostics = diagnostics.Diagnostics(
            self,
            "policy",
            self.managed_report(self._report),
            hardware_id=lambda: ", ".join(sorted(self.landers)),
        )
        self.landers: dict[str, int] = {}  # states received per lander_id (non-empty ids)

    def _configure(self) -> str:
        p = params.renamed(self, self._p, PARAMETERS, RENAMED)  # an old name warns here
        built = build_policy(p["controller"], p["model_path"], p["layer"], p["layer_settings"])
        self.policy, self.model_file = built.runtime, str(built.policy_file or "")
        if self.controller_name == DQN:
            # Warm up numpy so the first real state is answered as fast as the rest (not the
            # reference controllers: an MPC teacher would solve a plan for nothing).
            self.policy.bare_action((TABLE3.lo + TABLE3.hi) / 2)
        self.config_hash = self.policy.config.digest()
        # (lander_id, episode) the runtime's memory belongs to
        self._episode: tuple[str, int] | None = None
        self.landers = {}
        self._landers_period: set[str] = set()
        self._period_times: list[float] = []
        self._since = diagnostics.Since()

        self._times: deque[float] = deque(maxlen=100_000)
        self._since_log: list[float] = []
        self.answered = 0
        self.invalid = 0
        self.gaps = 0  # states of an episode that never arrived (step gaps)
        self.lost = 0  # DDS message-lost events
        # per lander_id: (episode, step) of the last state received
        self._last: dict[str, tuple[int, int]] = {}
        self._answered: tuple[str, int, int] | None = None  # lander, episode, step last answered
        self._last_cmd: ThrustCommand | None = None  # the command that answered it
        self.repeats = 0  # states answered already (a lockstep resend while we were busy)

        # Created after the model loaded: a publisher on lander/thrust_cmd means "ready".
        pub = self.create_lifecycle_publisher
        self._status_pub = self.own(pub(GuidanceStatus, names.GUIDANCE_TOPIC, qos.LOOP_PUB_QOS))
        self._cmd_pub = self.own(pub(ThrustCommand, names.COMMAND_TOPIC, qos.LOOP_PUB_QOS))
        self._state_sub = self.own(
            self.create_subscription(
                LanderState,
                names.STATE_TOPIC,
                self._on_state,
                qos.LOOP_SUB_QOS,
                event_callbacks=SubscriptionEventCallbacks(message_lost=self._on_lost),
            )
        )
        if p["stats_period_s"] > 0:
            self.own(self.create_timer(p["stats_period_s"], self._log_stats))
        # DDS discovery of the simulator takes a moment after start-up; say when it is done.
        self._connect_timer = self.own(self.create_timer(0.05, self._check_connected))
        return f"policy ready: {built.describe()}"

    def _activate(self) -> str:
        return "answering every state"

    def _deactivate(self) -> str:
        return "states are no longer answered"

    def _release(self) -> str:
        what = f"decision time overall: {self.decision_stats()}; {self._counts()}"
        self.get_logger().info(what)
        self.policy = None
        return f"policy released ({self.ignored} states ignored while not active)"

    def _check_connected(self) -> None:
        n = self._state_sub.get_publisher_count()
        if n > 0:
            self.get_logger().info(
                f"policy connected: {n} publisher(s) of {self._state_sub.topic_name} matched"
            )
            self._connect_timer.cancel()

    def _on_lost(self, info: Any) -> None:
        self.lost += int(info.total_count_change)
        self.get_logger().warning(
            f"{info.total_count_change} state(s) reported lost by DDS [{self.lost} lost so far]"
        )

    def _count_gap(self, msg: LanderState) -> None:
        last = self._last.get(msg.lander_id, (0, -1))
        episode, step = last
        if msg.episode == episode and msg.step > step + 1:
            self.gaps += msg.step - step - 1
            self.get_logger().warning(
                f"episode {episode}: states {step + 1}..{msg.step - 1} never arrived "
                f"[{self.gaps} missing so far]"
            )
        if (msg.episode, msg.step) > last:
            self._last[msg.lander_id] = (msg.episode, msg.step)

    def _count_lander(self, lander_id: str) -> None:
        """Count states per lander; a further lander is a set-up error: say so once."""
        if not lander_id:
            return  # a state naming no lander (a test or replay of an old bag)
        self._landers_period.add(lander_id)
        if lander_id not in self.landers and self.landers:
            self.get_logger().error(
                f"states of lander {lander_id!r} arrive on {self._state_sub.topic_name} besides "
                f"lander(s) {', '.join(sorted(self.landers))}: a second simulator shares these "
                "names (give each stack its own namespace, -r __ns:=/vehicle2). Each is answered "
                "with its own lander_id"
            )
        self.landers[lander_id] = self.landers.get(lander_id, 0) + 1

    def _on_state(self, msg: LanderState) -> None:
        if not self.active or self.policy is None:
            self.ignored += 1
            return
        t0 = time.perf_counter()
        self._count_lander(msg.lander_id)
        self._count_gap(msg)
        if msg.status != LanderState.FLYING:
            return  # the episode is over: nothing to answer
        if (msg.lander_id, msg.episode, msg.step) == self._answered:
            # Sent again (lockstep resend): our answer was on its way, or lost (sent before the
            # simulator's subscription matched). The same command goes again, not a new
            # decision: a slow controller would otherwise pile up solves of the same state, and
            # the simulator drops a second copy as a duplicate.
            self.repeats += 1
            if self._last_cmd is not None:
                self._cmd_pub.publish(self._last_cmd)
            return
        try:
            state = check_state(state_from_msg(msg))
            if (msg.lander_id, msg.episode) != self._episode:
                self._episode = (msg.lander_id, msg.episode)
                self.policy.begin_episode()
            action, decision = self.policy.step(state)
        except ValueError as exc:
            self.invalid += 1
            if self.invalid <= LOG_FIRST or self.invalid % 100 == 0:
                self.get_logger().warning(
                    f"state of episode {msg.episode} step {msg.step} rejected, no command "
                    f"sent: {exc} [{self.invalid} invalid states so far]"
                )
            return
        self._last_cmd = command_msg(msg, action, self.policy.thrust(action))
        self._cmd_pub.publish(self._last_cmd)
        dt = time.perf_counter() - t0
        self._status_pub.publish(guidance_msg(msg, decision, dt))
        self._answered = (msg.lander_id, msg.episode, msg.step)
        self._times.append(dt)
        self._since_log.append(dt)
        self._period_times.append(dt)
        self.answered += 1

    def decision_stats(self, samples: Any = None) -> str:
        a = np.asarray(self._times if samples is None else samples, dtype=float) * 1e3
        if a.size == 0:
            return "no states answered yet"
        return (
            f"{a.size} decisions: p50 {np.percentile(a, 50):.3f} ms, "
            f"p99 {np.percentile(a, 99):.3f} ms, max {a.max():.3f} ms"
        )

    def _counts(self) -> str:
        return (
            f"{self.answered} answered "
            f"({self.policy.describe() if self.policy else self.controller_name}), "
            f"{self.repeats} repeated, {self.invalid} invalid, {self.gaps} missing (step gaps), "
            f"{self.lost} lost (DDS) states in all"
        )

    def _log_stats(self) -> None:
        if self._since_log:
            self.get_logger().info(
                f"decision time (last period) {self.decision_stats(self._since_log)}; "
                f"{self._counts()}"
            )
            self._since_log = []

    def _report(self) -> diagnostics.Report:
        """/diagnostics of the last period (rules: pd_ros_common.diagnostics)."""
        period, self._period_times = np.asarray(self._period_times) * 1e3, []
        overall = np.asarray(self._times, dtype=float) * 1e3
        landers, self._landers_period = sorted(self._landers_period), set()
        d = self._since(invalid=self.invalid, gaps=self.gaps, lost=self.lost)
        r = diagnostics.Report(ok_message="answering" if period.size else "waiting for states")

        def pct(a: np.ndarray, q: float) -> float:
            return float(np.percentile(a, q)) if a.size else float("nan")

        share = diagnostics.counts_share(self.policy.counts, "network")
        r.values = {
            "controller": self.controller_name,
            "model file": self.model_file or "(none: reference controller)",
            "runtime config hash": self.config_hash,
            "runtime layer": "off" if self.policy.config.is_off else "on",
            "landers": ", ".join(sorted(self.landers)) or "none",
            "landers (last period)": ", ".join(landers) or "none",
            "answered": self.answered,
            "answered (last period)": int(period.size),
            "decision time p50 (ms)": pct(overall, 50),
            "decision time p99 (ms)": pct(overall, 99),
            "decision time p99 last period (ms)": pct(period, 99),
            "layer changed share": sum(share.values()),
            **{f"layer changed share ({k})": v for k, v in share.items()},
            **{f"decided by {k}": v for k, v in self.policy.counts.items()},
            "repeated states": self.repeats,
            "invalid states": self.invalid,
            "missing states (gaps)": self.gaps,
            "lost states (DDS)": self.lost,
            "ignored states (not active)": self.ignored,
            **diagnostics.readers(self._cmd_pub, self._status_pub),
        }
        r.rule(
            diagnostics.ERROR,
            len(landers) > 1,
            f"states of {len(landers)} landers ({', '.join(landers)}): a second simulator "
            "shares these names",
        )
        r.rule(diagnostics.WARN, d["invalid"] > 0, f"{int(d['invalid'])} invalid state(s)")
        r.rule(diagnostics.WARN, d["gaps"] > 0, f"{int(d['gaps'])} state(s) missing")
        r.rule(diagnostics.WARN, d["lost"] > 0, f"{int(d['lost'])} state(s) lost")
        slow = period.size > 0 and pct(period, 99) > diagnostics.SLOW_DECISION_S * 1e3
        r.rule(diagnostics.WARN, slow, f"decision time p99 {pct(period, 99):.1f} ms")
        return r


def main(args: list[str] | None = None) -> int:
    return run_node(
        NODE_NAME, __doc__ or "", PARAMETERS, PolicyNode, args, exit_codes=[(PolicyLoadError, 1)]
    )


if __name__ == "__main__":
    sys.exit(main())
