"""Episode bookkeeping and command validation for the simulator node (no rclpy).

`Simulator` wraps `pd_core.lander.Lander` the way pd_sim_node drives it: episodes are numbered from
1, each step waits for a thrust command that names the episode and step it answers, and a command
is applied only if it is valid for the step being flown and is the first valid one for that step (a
second command for an answered step, from a second policy node or a stray publisher, is rejected as
a "conflict", or a "duplicate" when it repeats the first). With `command_source` set, only commands
from the node of that name fly: a stray publisher cannot take a step even when it answers first
(rejected as "foreign"). A simulator run has an identity, `lander_id`: a command that names another
lander (`Command.lander_id`, echoed by the policy from the state it answers) is meant for a second
simulator on the same names; it is counted apart as foreign (`Counters.foreign_commands`, per other
lander in `foreign_by_lander`), never judged as stale or flown, and not counted as rejected. A
command naming no lander ("") is judged as before. Anything else is rejected with a reason,
counted, and never applied. An initial state is accepted only if the OCP would take it
(`pd_core.ocp.check_request`: above ground, above the dry mass, plausible magnitudes). When a step
has to be flown without a fresh command, the last applied command is held
(`missing_command="hold"`) or zero thrust is used (`"zero"`).

Flying the same seed, initial state and actions through `Simulator` and through
`PoweredDescentEnv` (the same `Lander`) gives bit-identical states: `Simulator.advance` calls
`env.step(action)`.

`pd_core.ticker.FixedRateTicker` is the wall-clock timer of the real-time mode: absolute
deadlines on the monotonic clock (no drift), missed periods are skipped, lateness is recorded
for jitter figures.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pd_core.actions import DEFAULT_ACTIONS, ActionSpace
from pd_core.commands import Command
from pd_core.config import DT_S, MAX_EPISODE_TIME_S, REWARD, TABLE3, StateRange
from pd_core.lander import Lander, Status
from pd_core.ocp.request import check_request
from pd_core.reward import missed_limits

MISSING_COMMAND_MODES = ("hold", "zero")
MAX_SIM_DELAY_STEPS = 50  # as pd_core.dispersions.Dispersions.delay_steps
MAX_NAV_SIGMA = (50.0, 5.0)  # largest navigation noise the simulator adds (m, m/s)
THRUST_SCALE_RANGE = (0.5, 1.5)  # delivered / commanded thrust the simulator accepts

# A command's thrust must equal the table thrust of its action to this tolerance (N). The policy
# sends the table value itself, so anything beyond rounding is a sender bug or a tampered message.
THRUST_MATCH_TOL_N = 1e-6


@dataclass(frozen=True)
class StepOutcome:
    """What one `Simulator.advance` did."""

    action: int | None  # the action commanded; None for zero thrust with no action
    thrust_n: tuple[float, float, float]  # the thrust the plant flew (delay_steps late)
    fresh: bool  # a command answering this step was applied (not held / zero)
    status: Status
    done: bool  # the episode ended with this step
    result: dict[str, Any] | None  # episode result when done


@dataclass
class Counters:
    """Totals over the simulator's life (all episodes)."""

    steps: int = 0
    episodes_started: int = 0
    episodes_finished: int = 0
    accepted_commands: int = 0
    rejected_commands: int = 0
    missed_commands: int = 0
    rejected_by_reason: dict[str, int] = field(default_factory=dict)
    foreign_commands: int = 0  # commands for another lander_id (not flown, not "rejected")
    foreign_by_lander: dict[str, int] = field(default_factory=dict)


def check_command(
    cmd: Command,
    episode: int | None,
    step: int | None,
    actions: ActionSpace = DEFAULT_ACTIONS,
    thrust_tol_n: float = THRUST_MATCH_TOL_N,
) -> tuple[str, str] | None:
    """None if `cmd` may be applied at (episode, step), else (kind, message) saying why not.

    kinds: "action" (unknown action), "thrust" (NaN/infinite or not the action's thrust),
    "stale" (answers an earlier step or episode), "ahead" (answers a step not flown yet),
    "idle" (no episode is running). Content is checked before timing, so a malformed command
    is reported as malformed even when it is also late. (`Simulator.submit` adds "conflict" and
    "duplicate": the step was answered already.)
    """
    a = cmd.action
    if isinstance(a, bool) or not isinstance(a, (int, np.integer)) or not 0 <= a < actions.n:
        return "action", f"unknown action {a!r}: valid actions are 0..{actions.n - 1}"
    t = np.asarray(cmd.thrust_n, dtype=float)
    if t.shape != (3,) or not np.all(np.isfinite(t)):
        return "thrust", f"thrust has NaN or infinite values: {t.tolist()}"
    expected = actions.table_n[int(a)]
    if np.max(np.abs(t - expected)) > thrust_tol_n:
        return "thrust", (
            f"thrust {t.tolist()} N does not match action {int(a)} ({expected.tolist()} N)"
        )
    if episode is None or step is None:
        return "idle", f"no episode is running (command for episode {cmd.episode} step {cmd.step})"
    if (cmd.episode, cmd.step) < (episode, step):
        return "stale", (
            f"stale command for episode {cmd.episode} step {cmd.step}; "
            f"the simulator is at episode {episode} step {step}"
        )
    if (cmd.episode, cmd.step) > (episode, step):
        return "ahead", (
            f"command for episode {cmd.episode} step {cmd.step} is ahead of the simulator "
            f"(episode {episode} step {step})"
        )
    return None


def check_source(cmd: Command, command_source: str) -> tuple[str, str] | None:
    """None if `cmd` comes from the node `command_source` names ("" accepts any publisher),
    else ("foreign", message). Checked first: a command from elsewhere is not ours to judge."""
    if not command_source or cmd.source == command_source:
        return None
    sender = f"node {cmd.source!r}" if cmd.source else "a publisher of unknown node"
    return "foreign", (
        f"command for episode {cmd.episode} step {cmd.step} from {sender}, not from "
        f"{command_source!r} (command_source): not flown"
    )


def check_lander(cmd: Command, lander_id: str) -> tuple[str, str] | None:
    """None if `cmd` is for the lander `lander_id` (or names none), else ("foreign", message)."""
    if not cmd.lander_id or not lander_id or cmd.lander_id == lander_id:
        return None
    return "foreign", (
        f"command for lander {cmd.lander_id!r} (episode {cmd.episode} step {cmd.step}) heard "
        f"by lander {lander_id!r}: another simulator shares these names; not flown"
    )


def answered_already(first: Command | None, cmd: Command) -> tuple[str, str]:
    """(kind, message) rejecting `cmd` for a step that `first` answered already."""
    a = first.action if first is not None else None
    kind = "duplicate" if a == cmd.action else "conflict"
    return kind, (
        f"episode {cmd.episode} step {cmd.step} was answered already (action {a}); "
        f"a later command with action {cmd.action} is not flown (first command wins)"
    )


def check_initial_state(state: np.ndarray) -> np.ndarray:
    """A float (7,) copy of an initial state the lander can fly from, else ValueError why not."""
    s = np.asarray(state, dtype=float)
    if s.shape != (7,):
        raise ValueError(f"state must have 7 entries [x, y, z, vx, vy, vz, m], got shape {s.shape}")
    why = check_request(s[0:3], s[3:6], s[6])
    if why is not None:
        raise ValueError(why)
    return s.copy()


def describe_end(status: Status, state: np.ndarray, time_s: float) -> str:
    """Human-readable reason an episode ended (Eq. 12 landing condition)."""
    pos, vel = state[0:3], state[3:6]
    r, v = float(np.linalg.norm(pos)), float(np.linalg.norm(vel))
    lim = f"(limits |r| < {REWARD.x_lim_m:g} m, |v| < {REWARD.v_lim_mps:g} m/s)"
    if status == Status.LANDED:
        return f"landed: touchdown at |r| = {r:.3f} m, |v| = {v:.3f} m/s {lim}"
    if status == Status.CRASHED:
        off, fast = missed_limits(pos, vel)
        why = []
        if off:
            why.append(f"|r| = {r:.2f} m off target")
        if fast:
            why.append(f"|v| = {v:.2f} m/s too fast")
        return f"crashed: touchdown with {' and '.join(why) or 'no margin'} {lim}"
    if status == Status.OUT_OF_TIME:
        return f"out of time: still flying at {time_s:.1f} s, altitude {float(pos[2]):.1f} m"
    return f"interrupted at {time_s:.1f} s (altitude {float(pos[2]):.1f} m) by a reset"


class Simulator:
    """A `Lander` plus episode numbering, command validation and counters.

    Typical loop: `reset()`; then per step `submit(cmd)` for every command received and
    `advance()` once per period (real time) or once `has_fresh_command` (lockstep).
    Not thread-safe: the node serialises calls with a lock.
    """

    def __init__(
        self,
        disturbance: bool = True,
        missing_command: str = "hold",
        max_time_s: float = MAX_EPISODE_TIME_S,
        initial_range: StateRange = TABLE3,
        actions: ActionSpace = DEFAULT_ACTIONS,
        dt_s: float = DT_S,
        seed: int | None = None,
        command_source: str = "",
        delay_steps: int = 0,
        nav_sigma: tuple[float, float] = (0.0, 0.0),
        thrust_scale: float = 1.0,
        lander_id: str = "",
    ) -> None:
        lo, hi = THRUST_SCALE_RANGE
        if not (math.isfinite(thrust_scale) and lo <= thrust_scale <= hi):
            raise ValueError(f"thrust_scale must be in [{lo:g}, {hi:g}], got {thrust_scale!r}")
        for value, top, unit in zip(nav_sigma, MAX_NAV_SIGMA, ("m", "m/s"), strict=True):
            if not (math.isfinite(value) and 0.0 <= value <= top):
                raise ValueError(f"navigation noise must be in [0, {top:g}] {unit}, got {value!r}")
        if not (isinstance(delay_steps, int) and 0 <= delay_steps <= MAX_SIM_DELAY_STEPS):
            raise ValueError(
                f"delay_steps must be an integer in [0, {MAX_SIM_DELAY_STEPS}], got {delay_steps!r}"
            )
        if missing_command not in MISSING_COMMAND_MODES:
            raise ValueError(
                f"missing_command must be one of {MISSING_COMMAND_MODES}, got {missing_command!r}"
            )
        if not (math.isfinite(max_time_s) and max_time_s >= dt_s):
            raise ValueError(f"max_time_s must be >= dt ({dt_s} s), got {max_time_s!r}")
        self.env = Lander(
            disturbance=disturbance,
            max_time_s=max_time_s,
            initial_range=initial_range,
            actions=actions,
            dt_s=dt_s,
        )
        self.actions = actions
        self.missing_command = missing_command
        self.command_source = command_source
        self.lander_id = lander_id
        """identity of this run: commands naming another lander are foreign ("": none checked)"""
        """only commands whose `source` is this node name fly ("": any publisher)"""
        self.delay_steps = delay_steps
        """actuation delay: the plant flies the command of this many steps earlier (a FIFO
        filled with zero thrust at reset, as `pd_core.dispersions`' `delay_steps`)"""
        self._fifo: deque[tuple[float, float, float]] = deque()
        self.thrust_scale = float(thrust_scale)
        """delivered / commanded thrust on every thruster (an engine out of spec, as a fixed
        `pd_core.dispersions` thrust error); the fuel flow follows the delivered thrust"""
        self.nav_sigma = np.array([nav_sigma[0]] * 3 + [nav_sigma[1]] * 3 + [0.0])
        """white noise (sd per axis, drawn each step) on the state published: position, velocity,
        none on the mass (as pd_core.dispersions' nav_* dispersions)"""
        self._nav_rng = np.random.default_rng([seed if seed is not None else 0, 1])
        self._nav_noise = np.zeros(7)
        self.counters = Counters()
        self.episode = 0  # number of the current (or last) episode; 0 before the first
        self.flying = False
        self._next_seed = seed  # used by the first reset that names no seed
        self._pending: Command | None = None
        self._last_action: int | None = None
        self._status = Status.FLYING
        self._initial = np.zeros(7)
        self._ep_rejected = 0
        self._ep_missed = 0
        self._ep_foreign = 0
        self._last_result: dict[str, Any] | None = None

    # ------------------------------------------------------------------ episode control
    @property
    def step(self) -> int:
        """Index of the step being flown (the state published last has this index)."""
        return self.env._steps

    @property
    def state(self) -> np.ndarray:
        return self.env.state

    @property
    def observed_state(self) -> np.ndarray:
        """The state as navigation reports it: the true state plus this step's noise."""
        return self.env.state + self._nav_noise

    @property
    def status(self) -> Status:
        return self._status

    @property
    def time_s(self) -> float:
        return self.env.time_s

    @property
    def last_result(self) -> dict[str, Any] | None:
        return self._last_result

    def reset(
        self, initial_state: np.ndarray | None = None, seed: int | None = None
    ) -> tuple[int, np.ndarray, dict[str, Any] | None]:
        """Start a new episode; (episode, initial state, result of an interrupted episode).

        `seed` None keeps the RNG running (the constructor's seed applies to the first reset);
        `initial_state` None samples the initial range (Table 3). ValueError for a bad state
        (the running episode then goes on untouched).
        """
        if initial_state is not None:
            initial_state = check_initial_state(initial_state)
        if seed is not None and seed < 0:
            raise ValueError(f"seed must be >= 0 or None, got {seed}")
        interrupted = self._finish(Status.FLYING) if self.flying else None
        if seed is None and self._next_seed is not None:
            seed = self._next_seed
        self._next_seed = None
        opts = {"initial_state": initial_state} if initial_state is not None else None
        _, info = self.env.reset(seed=seed, options=opts)
        self.episode += 1
        self.flying = True
        self._status = Status.FLYING
        self._initial = np.asarray(info["state"], dtype=float).copy()
        self._pending = None
        self._last_action = None
        self._fifo = deque([(0.0, 0.0, 0.0)] * self.delay_steps)
        if seed is not None:
            self._nav_rng = np.random.default_rng([seed, 1])  # a stream apart from the env's
        self._draw_nav_noise()
        self._ep_rejected = 0
        self._ep_missed = 0
        self._ep_foreign = 0
        self.counters.episodes_started += 1
        return self.episode, self._initial.copy(), interrupted

    # ------------------------------------------------------------------ commands
    def submit(self, cmd: Command) -> tuple[str, str] | None:
        """Validate and store a command for the current step; None or (kind, reason) if rejected.

        A command for another lander gives ("foreign", reason) and is counted as foreign only."""
        foreign = check_lander(cmd, self.lander_id)
        if foreign is not None:
            c = self.counters
            c.foreign_commands += 1
            c.foreign_by_lander[cmd.lander_id] = c.foreign_by_lander.get(cmd.lander_id, 0) + 1
            if self.flying:
                self._ep_foreign += 1
            return foreign
        where = (self.episode, self.step) if self.flying else (None, None)
        err = check_source(cmd, self.command_source) or check_command(
            cmd, *where, actions=self.actions
        )
        if err is None and self.has_fresh_command:
            err = answered_already(self._pending, cmd)
        if err is not None:
            self.counters.rejected_commands += 1
            by = self.counters.rejected_by_reason
            by[err[0]] = by.get(err[0], 0) + 1
            if self.flying:
                self._ep_rejected += 1
            return err
        self._pending = cmd  # the first valid command for this step wins
        self.counters.accepted_commands += 1
        return None

    @property
    def has_fresh_command(self) -> bool:
        """A valid command answering the current step has arrived (lockstep may advance)."""
        p = self._pending
        return self.flying and p is not None and (p.episode, p.step) == (self.episode, self.step)

    # ------------------------------------------------------------------ stepping
    def advance(self) -> StepOutcome:
        """Fly one step with the fresh command, else the held one or zero thrust."""
        if not self.flying:
            raise RuntimeError("no episode is running: call reset() first")
        fresh = self.has_fresh_command
        action: int | None
        if fresh:
            assert self._pending is not None
            action = int(self._pending.action)
        else:
            action = self._last_action if self.missing_command == "hold" else None
            self._ep_missed += 1
            self.counters.missed_commands += 1
        self._pending = None
        if action is None:
            thrust = (0.0, 0.0, 0.0)
        else:
            thrust = tuple(float(v) for v in self.actions.table_n[action])
            self._last_action = action
        if self.delay_steps:
            self._fifo.append(thrust)
            thrust = self._fifo.popleft()
        if self.thrust_scale != 1.0:
            thrust = tuple(self.thrust_scale * v for v in thrust)
        _, _, terminated, truncated, info = self.env.step_thrust(thrust)
        self._draw_nav_noise()
        self.counters.steps += 1
        self._status = Status(info["status"])
        result = None
        done = bool(terminated or truncated)
        if done:
            result = self._finish(self._status)
        return StepOutcome(action, thrust, fresh, self._status, done, result)

    def _draw_nav_noise(self) -> None:
        if self.nav_sigma.any():
            self._nav_noise = self._nav_rng.normal(size=7) * self.nav_sigma

    def _finish(self, status: Status) -> dict[str, Any]:
        s = self.env.state
        result = {
            "episode": self.episode,
            "steps": self.step,
            "time_of_flight": self.time_s,
            "initial_position": self._initial[0:3].copy(),
            "initial_velocity": self._initial[3:6].copy(),
            "final_position": s[0:3].copy(),
            "final_velocity": s[3:6].copy(),
            "final_mass": float(s[6]),
            "fuel": float(self._initial[6] - s[6]),
            "landed": status == Status.LANDED,
            "status": int(status),
            "reason": describe_end(status, s, self.time_s),
            "rejected_commands": self._ep_rejected,
            "missed_commands": self._ep_missed,
            "foreign_commands": self._ep_foreign,
            "lander_id": self.lander_id,
        }
        self.flying = False
        self._pending = None
        self.counters.episodes_finished += 1
        self._last_result = result
        return result
