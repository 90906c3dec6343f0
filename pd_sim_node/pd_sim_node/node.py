"""pd_sim_node: flies `pd_core.sim.Simulator` and speaks lander/state, lander/thrust_cmd,
lander/episode and sim/reset (relative names: /lander/... in the root namespace).

Real-time mode (default): one step of dt = 0.2 s and the new state every 1 / rate_hz seconds of
wall clock; a step whose command has not arrived by its tick is flown with the last applied
command held, or with zero thrust (`missing_command`). An episode started at start-up or by
sim/reset waits for the first command answering its step 0 before its clock starts (the state is
published again every `resend_s` meanwhile; `start_wait_s` can bound the wait). Lockstep mode:
a step is flown as soon as a valid command answering it has arrived, so an episode flies as fast
as the policy answers and is deterministic; without an answer within `resend_s` the state is
published again. With `auto_restart`, the next episode starts when one ends. The contract of
this pacing is `pd_core.sim_pacing.Pacing`. The first valid command for a step is flown; later
ones are rejected, counted and logged like every invalid command (`pd_core.sim`).

A managed (lifecycle) node: configure makes the simulator and, with `start_episode`, its first
episode; activate publishes its state and starts flying; deactivate holds the episode at its step
(no state, no step; commands that arrive are kept) and activate goes on from that step, so
nothing is lost or flown twice; sim/reset is refused unless active; cleanup drops the simulator.
`autostart` (default true) configures and activates it at start-up.

Identity: each run has a `lander_id` (the parameter, or a random one at start-up), carried by
every lander/state and echoed by the command answering it. A command for another lander (a
second stack on the same names, without a namespace) is counted as foreign, never flown, and the
first one of each other lander is logged as an error naming it; /diagnostics is then at ERROR.
sim/reset refuses a request for another lander, and one naming none while another is heard
(`pd_core.sim_pacing.ResetGate`).

Its rooms: the parameters (`pd_sim_node.parameters`; all read at start-up, read-only afterwards;
defaults in pd_bringup/config/sim.yaml), what it publishes, viewers' lander/odom, lander/path and
lockstep /clock included (`pd_sim_node.outputs`), lander/thrust_cmd in (`pd_sim_node.inputs`),
sim/reset (`pd_sim_node.reset`), /diagnostics and its log lines (`pd_sim_node.report`). This
module is the node that joins them: one lock serialises the callbacks, the clock and the
transitions.
"""

from __future__ import annotations

import secrets
import sys
import threading
import time
from typing import Any

import numpy as np

from pd_core.commands import Command
from pd_core.sim import Simulator
from pd_core.sim_pacing import Do, Pacing, ResetGate
from pd_ros_common import diagnostics, params
from pd_ros_common.lifecycle import ManagedNode
from pd_ros_common.run import run_node
from pd_sim_node import report
from pd_sim_node.inputs import CommandInput
from pd_sim_node.outputs import Outputs
from pd_sim_node.parameters import (
    CHECKS,
    OLD_AUTOSTART,
    PARAMETERS,
    make_simulator,
    old_autostart,
    ready_line,
)
from pd_sim_node.reset import ResetService

NODE_NAME = "pd_sim_node"
__all__ = ["CHECKS", "NODE_NAME", "PARAMETERS", "SimNode", "main"]


class SimNode(ManagedNode):
    """Thin ROS adapter: messages in, `Simulator` calls, messages out; when to step is the
    `Pacing`'s answer. configure makes the simulator (and its first episode), activate flies
    it; inactive, it holds its step."""

    def __init__(self, **kwargs: Any) -> None:
        # Before Node.__init__: destroy_node must work whatever fails after this point.
        self._lock = threading.Lock()
        self._pacing: Pacing | None = None
        self._sim: Simulator | None = None
        super().__init__(NODE_NAME, **kwargs)
        p = self._p = params.declare(self, PARAMETERS, CHECKS)
        self.autostart, self.start_episode = p["autostart"], p["start_episode"]
        if old_autostart(p, self._parameter_overrides):
            self.get_logger().warning(OLD_AUTOSTART)
            self.autostart, self.start_episode = True, False
        self.lockstep = p["lockstep"]
        self.lander_id = p["lander_id"] or secrets.token_hex(4)
        self._pacing = Pacing(
            lockstep=self.lockstep,
            rate_hz=p["rate_hz"],
            resend_s=p["resend_s"],
            start_wait_s=p["start_wait_s"],
            auto_restart=p["auto_restart"],
            on_tick=self._tick,
            tick_priority=p["tick_priority"],
        )
        self._gate = ResetGate(self.lander_id)
        self._reset = ResetService(
            self, self._gate, self._reset_episode, self._episode, self._other_landers
        )
        self._report = report.SimReport(
            self.lander_id, self.lockstep, p["rate_hz"], time.monotonic()
        )
        self.diagnostics = diagnostics.Diagnostics(
            self, "simulator", self.managed_report(self._diagnose), hardware_id=self.lander_id
        )

    def _configure(self) -> str:
        p, pacing = self._p, self._pacing
        self._sim = make_simulator(p, self.lander_id)
        pacing.configure(time.monotonic())
        self._unpublished = False  # a state made while not active: published on activate
        nav_sigma = (p["nav_position_sigma_m"], p["nav_velocity_sigma_mps"])
        self._out = Outputs(self, self.lander_id, self.lockstep, nav_sigma)
        self._in = CommandInput(
            self,
            self._on_command,
            self._out.state_pub,
            named_sources=bool(p["command_source"]),
            log_rejections=p["log_rejections"],
        )
        if p["path_period_s"] > 0:
            self.own(self.create_timer(p["path_period_s"], self._path_timer))
        self.own(self.create_timer(min(pacing.resend_s or 0.5, 0.5) / 2, self._resend_check))
        if self.start_episode:
            init = p["initial_state"]
            state = np.asarray(init, dtype=float) if len(init) == 7 else None
            with self._lock:
                self._start_episode(state, None, wait=True)
        return ready_line(p, self.lander_id)

    def _activate(self) -> str:
        with self._lock:
            s = self._sim
            if self._unpublished:
                self._unpublished = False
                self._publish_state()
            if self._pacing.activate(time.monotonic(), s.flying, s.has_fresh_command) is Do.ADVANCE:
                self._advance()
            where = report.where(s)
            return f"flying, {where}" if s.flying else f"{where}; idle"

    def _deactivate(self) -> str:
        with self._lock:
            self._pacing.deactivate()
            return f"{report.where(self._sim)} held"

    def _release(self) -> str:
        with self._lock:
            self._pacing.stop_clock()
            s, self._sim = self._sim, None
        if s is None:
            return "nothing held"
        dropped = f"; episode {s.episode} at step {s.step} dropped" if s.flying else ""
        return f"simulator released after {s.counters.episodes_started} episode(s){dropped}"

    # ------------------------------------------------------------------ episodes
    def _start_episode(self, initial_state: np.ndarray | None, seed: int | None, wait: bool) -> int:
        """Reset the simulator and publish step 0 (caller holds the lock). ValueError passes.
        Its clock starts as `Pacing.start_episode` says (`wait`: for its first command)."""
        episode, init, interrupted = self._sim.reset(initial_state, seed)
        if interrupted is not None:
            self._publish_result(interrupted)
        started = self._sim.counters.episodes_started
        self._pacing.start_episode(started, wait, self.active, time.monotonic())
        self._out.new_episode()
        self.get_logger().info(report.start_line(episode, init))
        self._publish_state()
        return episode

    def _reset_episode(self, state: np.ndarray | None, seed: int | None) -> tuple[int, Any]:
        """sim/reset: an episode that waits for its first command; (episode, initial state)."""
        with self._lock:
            return self._start_episode(state, seed, wait=True), self._sim.state

    def _episode(self) -> int:
        return self._sim.episode if self._sim is not None else 0

    def _other_landers(self) -> list[str]:
        with self._lock:
            return list(self._sim.counters.foreign_by_lander)

    def _tick(self, ticker: Any) -> None:
        """One call of the real-time clock, on its thread."""
        with self._lock:
            refused = self._pacing.priority_refused(ticker)
            if refused:
                self.get_logger().warning(refused)
            try:
                what = self._pacing.tick(ticker, self._sim is not None and self._sim.flying)
                if what is Do.ADVANCE:
                    self._advance()
                elif what is Do.START_EPISODE:
                    self._start_episode(None, None, wait=False)  # replaces this ticker
            except Exception as exc:  # never let the clock thread die silently
                self.get_logger().error(f"simulation step failed: {exc!r}")

    def _advance(self) -> None:
        """One step with whatever command the simulator holds; publish state and result."""
        out = self._sim.advance()
        then = self._pacing.advanced(out.done)
        self._publish_state()
        if out.done:
            self._publish_result(out.result)
        if then is Do.START_EPISODE:
            self._start_episode(None, None, wait=False)

    def _publish_state(self) -> None:
        if not self.active:  # the first episode, made by configure: published on activate
            self._unpublished = True
            return
        self._out.state(self._sim, self._pacing.clock_ns)
        self._pacing.published(time.monotonic())

    def _path_timer(self) -> None:
        with self._lock:
            if self.active and self._sim.flying and self._out.path_changed:
                self._out.publish_path()

    def _publish_result(self, result: dict[str, Any]) -> None:
        self._out.result(result)
        lateness = self._pacing.lateness_ms()
        line = report.episode_line(result, self._sim.counters, self._in.lost, lateness)
        self.get_logger().info(line)

    # ------------------------------------------------------------------ callbacks
    def _on_command(self, cmd: Command) -> None:
        with self._lock:
            if self._sim is None:
                return
            known = cmd.lander_id in self._sim.counters.foreign_by_lander
            err = self._sim.submit(cmd)
            if self._gate.command(err and err[0], cmd.lander_id, time.monotonic()):
                if not known:  # once per other lander: it is a set-up error, not a command's
                    self._in.foreign(cmd.lander_id, self.lander_id)
                return
            if err is not None:
                self._in.rejected(err, self._sim.counters.rejected_commands)
                return
            if not self.active:
                return  # held: activate flies it
            what = self._pacing.on_command(self._sim.has_fresh_command, time.monotonic())
            if what is Do.ADVANCE:
                self._advance()
            elif what is Do.CLOCK_STARTED:
                self.get_logger().info(
                    f"first command of episode {self._sim.episode} after "
                    f"{self._pacing.waited_s:.1f} s: the clock starts"
                )

    def _resend_check(self) -> None:
        with self._lock:
            if not self.active:
                return
            what = self._pacing.due(time.monotonic(), self._sim.flying)
            if what is Do.WAIT_EXPIRED:
                self.get_logger().warning(
                    f"no command for step 0 of episode {self._sim.episode} within "
                    f"{self._pacing.start_wait_s:g} s: flying without (missing_command applies)"
                )
            elif what is Do.RESEND:
                if self.lockstep:
                    self.get_logger().info(
                        f"lockstep: no answer for step {self._sim.step} after "
                        f"{self._pacing.resend_s:g} s; publishing the state again"
                    )
                self._publish_state()

    def _diagnose(self) -> diagnostics.Report:
        """/diagnostics of the last period (`report.SimReport`) and the writers' readers."""
        now = time.monotonic()
        with self._lock:
            r = self._report(self._sim, self._in.lost, now)
        r.values.update(self._out.readers())
        return r

    def destroy_node(self) -> None:
        with self._lock:
            ticker = self._pacing.take_ticker() if self._pacing is not None else None
        if ticker is not None:
            ticker.stop()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    return run_node(NODE_NAME, __doc__ or "", PARAMETERS, SimNode, args)


if __name__ == "__main__":
    sys.exit(main())
