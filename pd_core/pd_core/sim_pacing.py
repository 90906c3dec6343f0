"""When the simulator node steps its `pd_core.sim.Simulator`, and who may restart it: the
episode pacing and the reset gate of pd_sim_node as plain Python (no rclpy), unit-tested without
a ROS context, a thread or a clock.

Contract of `Pacing` (pd_sim_node's docstring says the same to users):

- Lockstep: a step is flown as soon as the simulator holds a fresh valid command for it
  (`on_command` answers ADVANCE). No wall clock runs; when an episode ends with `auto_restart`,
  the next one starts at once (`advanced` answers START_EPISODE).
- Real time: a clock (`pd_core.ticker.FixedRateTicker`, one fresh per start so that every step
  lasts a full period) calls the node every 1 / rate_hz s, and each call flies one step
  (`tick` answers ADVANCE). An episode started with `wait` (at start-up or by sim/reset) and
  `start_wait_s != 0` starts its clock when its first command arrives (`on_command` answers
  CLOCK_STARTED, `waited_s` says after how long); with `start_wait_s > 0` the wait ends after
  that long and the clock starts without one (`due` answers WAIT_EXPIRED). An episode started
  without `wait` (auto_restart) starts its clock at once. When an episode ends, the clock stops,
  or with `auto_restart` its next call starts the next episode (`tick` answers START_EPISODE).
- Resend: while a lockstep step waits for its answer, or a real-time episode for its first
  command, `due` answers RESEND once `resend_s` passed since the state was last published
  (0 = never).
- Inactive (lifecycle): the clock is held, never run: `deactivate` stops it and remembers that
  it ran; `activate` starts a fresh one, or starts it for a first command that arrived
  meanwhile, or restarts a first command's wait, or (lockstep) flies an answer that arrived
  meanwhile (ADVANCE).
- Simulation clock: `clock_ns` grows by one step (DT_NS) per step flown and by one more between
  two episodes, from 0 at `configure` (lockstep's /clock).
- Tick lateness: the lateness of every clock call is kept (the last `KEEP_LATENESS`) for the
  end-of-episode line (`lateness_ms`, real time only).

Mechanism: the node holds one `Pacing` under its lock, tells it what happened with the monotonic
time `now`, and does what the answer (`Do`) says; the pacing starts and stops the clock itself
(`make_ticker`, a `FixedRateTicker` by default, a fake in tests). Not thread-safe.

`ResetGate` says whether sim/reset may start an episode: not while the node is not active, not
for another lander (answered `REFUSE_DELAY_S` late, so that lander's own answer reaches the
client first), and not for a request naming no lander within `AMBIGUOUS_S` of a command for
another lander (two stacks share the names: the request is ambiguous).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from enum import Enum
from typing import Any

from pd_core.config import DT_S
from pd_core.ticker import FixedRateTicker, percentiles_ms

DT_NS = round(DT_S * 1e9)  # one step of the simulation clock (integer ns)
AMBIGUOUS_S = 5.0  # a reset naming no lander is refused this long after a foreign command
REFUSE_DELAY_S = 1.0  # a reset for another lander is refused this much later
KEEP_LATENESS = 10000  # tick lateness samples kept for the end-of-episode line


class Do(Enum):
    """What the node does after telling its `Pacing` what happened."""

    NOTHING = "nothing"
    ADVANCE = "advance"  # fly one step now, with the command the simulator holds
    START_EPISODE = "start episode"  # start the next episode now (auto_restart, no wait)
    RESEND = "resend"  # publish the current state again
    CLOCK_STARTED = "clock started"  # the first command came: the clock runs (say so)
    WAIT_EXPIRED = "wait expired"  # start_wait_s passed: the clock runs without a command


class Pacing:
    """The pacing state machine of one simulator node (see the module docstring).

    `on_tick(ticker)` is what each clock call runs (the node's tick: it takes the node's lock
    and asks `tick`); `make_ticker(period_s, fn, name=, priority=)` makes the clock."""

    def __init__(
        self,
        *,
        lockstep: bool,
        rate_hz: float,
        resend_s: float,
        start_wait_s: float,
        auto_restart: bool,
        on_tick: Callable[[Any], None],
        tick_priority: int = 0,
        make_ticker: Callable[..., Any] = FixedRateTicker,
    ) -> None:
        self.lockstep = lockstep
        self.rate_hz = rate_hz
        self.resend_s = resend_s
        self.start_wait_s = 0.0 if lockstep else start_wait_s  # lockstep never waits
        self.auto_restart = auto_restart
        self.tick_priority = tick_priority  # 0 once SCHED_FIFO was refused: not tried again
        self._on_tick = on_tick
        self._make_ticker = make_ticker
        self.ticker: Any = None  # the running clock (real time), None when stopped
        self.waited_s = 0.0  # how long the last first-command wait lasted (CLOCK_STARTED)
        self.configure(now=0.0)

    def configure(self, now: float) -> None:
        """A fresh configuration: no episode waiting or due, the simulation clock at 0, no
        lateness kept, the state counted as published `now`. The clock must be stopped."""
        self.clock_ns = 0
        self.waiting_since: float | None = None  # real time: episode waits for its 1st command
        self.restart_due = False  # an episode ended with auto_restart: the next tick starts one
        self.resume_clock = False  # a clock was (or would be) running when not active
        self.last_publish = now
        self.lateness_s: list[float] = []

    # ------------------------------------------------------------------ episodes
    def start_episode(self, episodes_started: int, wait: bool, active: bool, now: float) -> None:
        """An episode was just reset (the `episodes_started`-th): one step on the simulation
        clock between two episodes; the clock starts now, or (real time, `wait` and
        start_wait_s != 0) when its first command arrives."""
        if episodes_started > 1:
            self.clock_ns += DT_NS
        self.restart_due = False
        self.stop_clock()
        self.waiting_since = None
        if self.lockstep:
            return
        if wait and self.start_wait_s != 0:
            self.waiting_since = now
        else:
            self.start_clock(active)

    def advanced(self, done: bool) -> Do:
        """One step was flown (`done`: it ended the episode). START_EPISODE in lockstep with
        auto_restart; else, at an end, the clock stops unless auto_restart is due."""
        self.clock_ns += DT_NS
        if not done:
            return Do.NOTHING
        self.restart_due = self.auto_restart
        if self.lockstep and self.auto_restart:
            return Do.START_EPISODE
        if not self.restart_due:
            self.stop_clock()
        return Do.NOTHING

    def published(self, now: float) -> None:
        """The state was published `now` (the resend delay counts from here)."""
        self.last_publish = now

    # ------------------------------------------------------------------ events (node active)
    def on_command(self, fresh: bool, now: float) -> Do:
        """A command was accepted while the node is active (`fresh`: the simulator holds one
        for the current step): ADVANCE in lockstep, or the first command starts the clock."""
        if self.lockstep and fresh:
            return Do.ADVANCE
        if self.waiting_since is not None and fresh:
            self.waited_s = now - self.waiting_since
            self.start_clock(active=True)
            return Do.CLOCK_STARTED
        return Do.NOTHING

    def due(self, now: float, flying: bool) -> Do:
        """The periodic check while the node is active: WAIT_EXPIRED (the clock now runs) or
        RESEND while a step waits for its answer (lockstep) or its first command (real time)."""
        if not flying or (not self.lockstep and self.waiting_since is None):
            return Do.NOTHING
        waited = now - self.waiting_since if self.waiting_since is not None else 0.0
        if self.start_wait_s > 0 and waited > self.start_wait_s:
            self.start_clock(active=True)
            return Do.WAIT_EXPIRED
        if self.resend_s > 0 and now - self.last_publish >= self.resend_s:
            return Do.RESEND
        return Do.NOTHING

    def tick(self, ticker: Any, flying: bool) -> Do:
        """A call of `ticker`: ADVANCE while flying, START_EPISODE when a restart is due; a
        ticker that is not the current clock (superseded by a reset) or has nothing left to fly
        is stopped (without a join: it may wait for the caller's lock)."""
        if ticker is not self.ticker:
            ticker.stop(join=False)
            return Do.NOTHING
        if flying:
            return Do.ADVANCE
        if self.restart_due:
            return Do.START_EPISODE
        ticker.stop(join=False)
        return Do.NOTHING

    def priority_refused(self, ticker: Any) -> str | None:
        """The ticker's SCHED_FIFO refusal, once (later clocks then run without asking)."""
        why = ticker.priority_error
        if why:
            self.tick_priority = 0
            ticker.priority_error = None
        return why or None

    # ------------------------------------------------------------------ lifecycle
    def activate(self, now: float, flying: bool, fresh: bool) -> Do:
        """The node became active: resume what `deactivate` held (see the module docstring)."""
        self.last_publish = now  # an answer in flight has resend_s to land
        if flying and self.waiting_since is not None:
            if fresh:  # the first command came while the node was inactive
                self.start_clock(active=True)
            else:
                self.waiting_since = now
        elif self.resume_clock:
            self.start_clock(active=True)
        elif self.lockstep and flying and fresh:
            return Do.ADVANCE  # the answer came while the node was inactive
        return Do.NOTHING

    def deactivate(self) -> None:
        """The node became inactive: stop the clock, remembering whether it ran."""
        running = self.ticker is not None or self.resume_clock
        self.stop_clock()
        self.resume_clock = running

    # ------------------------------------------------------------------ the clock
    def start_clock(self, active: bool) -> None:
        """Start a fresh clock (ends any wait); while inactive only remember to on activate."""
        self.stop_clock()
        self.waiting_since = None
        if not active:
            self.resume_clock = True
            return
        ticker = self._make_ticker(
            1.0 / self.rate_hz,
            lambda: self._on_tick(ticker),
            name="sim-tick",
            priority=self.tick_priority,
        )
        self.ticker = ticker
        ticker.start()

    def stop_clock(self) -> None:
        """Stop the clock (without a join: it may wait for the caller's lock); keep its lateness."""
        self.resume_clock = False
        if self.ticker is not None:
            self._keep_lateness(self.ticker)
            self.ticker.stop(join=False)
            self.ticker = None

    def take_ticker(self) -> Any:
        """Hand the running clock over (to stop and join it outside the lock); None if none."""
        ticker, self.ticker = self.ticker, None
        return ticker

    def lateness_ms(self) -> dict[str, float] | None:
        """Percentiles (ms) of the clock calls' lateness so far; None in lockstep or before one."""
        if self.ticker is not None:
            self._keep_lateness(self.ticker)
        if not self.lateness_s or self.lockstep:
            return None
        return percentiles_ms(self.lateness_s)

    def _keep_lateness(self, ticker: Any) -> None:
        self.lateness_s.extend(ticker.lateness_s)
        ticker.lateness_s = []
        del self.lateness_s[:-KEEP_LATENESS]


class ResetGate:
    """Whether sim/reset may start an episode of lander `lander_id` (see the module docstring)."""

    def __init__(self, lander_id: str) -> None:
        self.lander_id = lander_id
        self.foreign_at = -math.inf  # monotonic time of the last command for another lander

    def command(self, reason: str | None, lander_id: str, now: float) -> bool:
        """A command was judged (`reason`: the simulator's rejection kind, None if accepted):
        True, and remembered, when it was for another lander."""
        if reason == "foreign" and lander_id not in ("", self.lander_id):
            self.foreign_at = now
            return True
        return False

    def judge(
        self, refusal: str, requested: str, now: float, others: Callable[[], Iterable[str]]
    ) -> tuple[str | None, float]:
        """(why the reset is refused or None, seconds to wait before answering): `refusal` is
        the node's own reason ("" when active), `requested` the lander the request names ("" =
        none), `others()` the other landers heard (asked only for an ambiguous request)."""
        if refusal:
            return f"reset refused: {refusal}", 0.0
        if requested and requested != self.lander_id:
            why = f"reset refused: it is for lander {requested!r}, this is {self.lander_id!r}"
            return why, REFUSE_DELAY_S  # the named lander answers first
        if not requested and now - self.foreign_at < AMBIGUOUS_S:
            return (
                f"reset refused: ambiguous, lander {self.lander_id!r} shares its names with "
                f"{', '.join(sorted(others()))}; name the lander (ResetEpisode.lander_id)"
            ), 0.0
        return None, 0.0
