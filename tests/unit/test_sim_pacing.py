"""pd_core.sim_pacing: when the simulator node steps (lockstep, real time, the first command's
wait, resends, restarts, the held clock of an inactive node), the simulation clock, and the
reset gate. A fake ticker stands in for the wall clock: no thread, no sleep, times given."""

from __future__ import annotations

import math

import pytest

from pd_core.config import DT_S
from pd_core.sim_pacing import (
    AMBIGUOUS_S,
    DT_NS,
    KEEP_LATENESS,
    REFUSE_DELAY_S,
    Do,
    Pacing,
    ResetGate,
)


class FakeTicker:
    """Records what `FixedRateTicker` would have been asked."""

    def __init__(self, period_s, fn, name="ticker", priority=0):
        self.period_s, self.fn, self.name, self.priority = period_s, fn, name, priority
        self.started = self.stopped = False
        self.joined: bool | None = None
        self.lateness_s: list[float] = []
        self.priority_error: str | None = None

    def start(self):
        self.started = True

    def stop(self, join=True, timeout_s=2.0):
        self.stopped, self.joined = True, join


def pacing(**kw) -> tuple[Pacing, list[FakeTicker], list[FakeTicker]]:
    """A Pacing on fake tickers: (pacing, tickers made, tickers whose call ran)."""
    made: list[FakeTicker] = []
    ticked: list[FakeTicker] = []

    def make(*a, **k):
        made.append(FakeTicker(*a, **k))
        return made[-1]

    args = dict(lockstep=False, rate_hz=5.0, resend_s=1.0, start_wait_s=-1.0, auto_restart=False)
    p = Pacing(**{**args, **kw}, on_tick=ticked.append, make_ticker=make)
    return p, made, ticked


def test_one_step_of_the_simulation_clock_is_dt():
    assert DT_NS == 200_000_000 == round(DT_S * 1e9)


def test_lockstep_advances_on_a_fresh_command_and_never_runs_a_clock():
    p, made, _ = pacing(lockstep=True, start_wait_s=-1.0)
    assert p.start_wait_s == 0.0  # lockstep never waits for a first command
    p.start_episode(1, wait=True, active=True, now=10.0)
    assert p.waiting_since is None and made == []
    assert p.on_command(fresh=False, now=10.1) is Do.NOTHING
    assert p.on_command(fresh=True, now=10.2) is Do.ADVANCE
    for _ in range(3):
        assert p.advanced(done=False) is Do.NOTHING
    assert p.clock_ns == 3 * DT_NS == 600_000_000
    assert made == []


def test_the_simulation_clock_adds_one_step_between_episodes_and_restarts_at_configure():
    p, _, _ = pacing(lockstep=True)
    p.start_episode(1, wait=False, active=True, now=0.0)
    p.advanced(done=False)
    p.advanced(done=True)
    assert p.clock_ns == 400_000_000
    p.start_episode(2, wait=False, active=True, now=1.0)  # the second episode: one step more
    assert p.clock_ns == 600_000_000
    p.configure(now=5.0)
    assert (p.clock_ns, p.last_publish, p.restart_due, p.lateness_s) == (0, 5.0, False, [])


@pytest.mark.parametrize("auto_restart, expected", [(True, Do.START_EPISODE), (False, Do.NOTHING)])
def test_lockstep_end_of_episode_restarts_at_once_only_with_auto_restart(auto_restart, expected):
    p, _, _ = pacing(lockstep=True, auto_restart=auto_restart)
    p.start_episode(1, wait=False, active=True, now=0.0)
    assert p.advanced(done=True) is expected
    assert p.restart_due is auto_restart


def test_real_time_episode_waits_for_its_first_command_then_starts_a_clock_at_rate_hz():
    p, made, ticked = pacing(rate_hz=4.0, tick_priority=7)
    p.start_episode(1, wait=True, active=True, now=10.0)
    assert p.waiting_since == 10.0 and made == []
    assert p.on_command(fresh=False, now=11.0) is Do.NOTHING  # e.g. held, not for this step
    assert p.on_command(fresh=True, now=12.5) is Do.CLOCK_STARTED
    assert p.waited_s == pytest.approx(2.5)
    assert p.waiting_since is None
    (t,) = made
    assert (t.period_s, t.name, t.priority, t.started) == (0.25, "sim-tick", 7, True)
    t.fn()  # a call of the clock runs the node's tick with that very ticker
    assert ticked == [t]
    assert p.on_command(fresh=True, now=12.6) is Do.NOTHING  # the clock paces from now on


def test_real_time_start_without_wait_or_with_start_wait_zero_starts_the_clock_at_once():
    p, made, _ = pacing(start_wait_s=0.0)
    p.start_episode(1, wait=True, active=True, now=0.0)
    assert len(made) == 1 and made[0].started and p.waiting_since is None
    q, made_q, _ = pacing(start_wait_s=-1.0)
    q.start_episode(1, wait=False, active=True, now=0.0)  # auto_restart's episodes
    assert len(made_q) == 1 and made_q[0].started


def test_a_bounded_first_command_wait_expires_and_resends_come_meanwhile():
    p, made, _ = pacing(start_wait_s=3.0, resend_s=1.0)
    p.start_episode(1, wait=True, active=True, now=10.0)
    p.published(10.0)
    assert p.due(10.9, flying=True) is Do.NOTHING
    assert p.due(11.0, flying=True) is Do.RESEND
    p.published(11.0)
    assert p.due(12.0, flying=True) is Do.RESEND
    p.published(12.0)
    assert p.due(13.0, flying=True) is Do.RESEND  # waited exactly 3.0 s: not yet over
    p.published(13.0)
    assert made == []
    assert p.due(13.1, flying=True) is Do.WAIT_EXPIRED
    assert len(made) == 1 and made[0].started
    assert p.due(20.0, flying=True) is Do.NOTHING  # the clock runs: nothing is resent


def test_an_unbounded_wait_never_expires():
    p, made, _ = pacing(start_wait_s=-1.0, resend_s=0.0)
    p.start_episode(1, wait=True, active=True, now=0.0)
    assert p.due(1e6, flying=True) is Do.NOTHING  # resend_s 0: never resent either
    assert made == [] and p.waiting_since == 0.0


def test_lockstep_resends_after_resend_s_and_not_after_the_episode():
    p, _, _ = pacing(lockstep=True, resend_s=2.0)
    p.start_episode(1, wait=True, active=True, now=0.0)
    p.published(100.0)
    assert p.due(101.99, flying=True) is Do.NOTHING
    assert p.due(102.0, flying=True) is Do.RESEND
    assert p.due(200.0, flying=False) is Do.NOTHING


def test_tick_advances_while_flying_restarts_when_due_and_otherwise_stops_its_ticker():
    p, made, _ = pacing(auto_restart=True)
    p.start_episode(1, wait=False, active=True, now=0.0)
    (t,) = made
    assert p.tick(t, flying=True) is Do.ADVANCE
    assert p.advanced(done=True) is Do.NOTHING  # real time: the next tick restarts
    assert p.restart_due and p.ticker is t and not t.stopped
    assert p.tick(t, flying=False) is Do.START_EPISODE
    p.start_episode(2, wait=False, active=True, now=0.2)
    assert t.stopped and t.joined is False  # superseded without a join (it waits for the lock)
    t2 = made[1]
    assert p.tick(t, flying=True) is Do.NOTHING  # a call of the old ticker does nothing
    assert p.tick(t2, flying=True) is Do.ADVANCE
    p.restart_due = False
    assert p.tick(t2, flying=False) is Do.NOTHING
    assert t2.stopped


def test_end_of_episode_without_auto_restart_stops_the_clock_and_keeps_its_lateness():
    p, made, _ = pacing()
    p.start_episode(1, wait=False, active=True, now=0.0)
    (t,) = made
    t.lateness_s = [0.001, 0.002, 0.003]
    assert p.advanced(done=True) is Do.NOTHING
    assert t.stopped and p.ticker is None and not p.restart_due
    q = p.lateness_ms()
    assert q["n"] == 3 and q["p50"] == pytest.approx(2.0) and q["max"] == pytest.approx(3.0)


def test_lateness_keeps_the_last_samples_of_the_running_clock_and_none_in_lockstep():
    p, made, _ = pacing()
    p.start_episode(1, wait=False, active=True, now=0.0)
    made[0].lateness_s = [0.0] * KEEP_LATENESS + [0.004] * 10
    q = p.lateness_ms()
    assert q["n"] == KEEP_LATENESS and q["max"] == pytest.approx(4.0)
    assert made[0].lateness_s == []  # taken over, not counted twice
    assert p.lateness_ms()["n"] == KEEP_LATENESS
    lock, _, _ = pacing(lockstep=True)
    lock.lateness_s = [0.001]
    assert lock.lateness_ms() is None
    assert pacing()[0].lateness_ms() is None  # no sample yet


def test_an_inactive_node_holds_the_clock_and_activate_starts_a_fresh_one():
    p, made, _ = pacing()
    p.start_episode(1, wait=False, active=False, now=0.0)  # configure's first episode
    assert made == [] and p.resume_clock
    assert p.activate(5.0, flying=True, fresh=False) is Do.NOTHING
    assert len(made) == 1 and made[0].started and p.last_publish == 5.0
    p.deactivate()
    assert made[0].stopped and p.ticker is None and p.resume_clock
    p.deactivate()  # twice: still remembered
    assert p.resume_clock
    p.activate(9.0, flying=True, fresh=False)
    assert len(made) == 2 and made[1] is p.ticker and made[1].started


def test_activate_during_a_first_command_wait_starts_the_clock_or_restarts_the_wait():
    p, made, _ = pacing()
    p.start_episode(1, wait=True, active=False, now=0.0)
    p.deactivate()
    assert not p.resume_clock  # a waiting episode has no clock to resume
    assert p.activate(30.0, flying=True, fresh=False) is Do.NOTHING
    assert p.waiting_since == 30.0 and made == []  # the wait counts from activate
    p.deactivate()
    assert p.activate(40.0, flying=True, fresh=True) is Do.NOTHING  # came while inactive
    assert len(made) == 1 and p.waiting_since is None


def test_lockstep_activate_flies_an_answer_that_came_while_inactive():
    p, made, _ = pacing(lockstep=True)
    p.start_episode(1, wait=True, active=False, now=0.0)
    assert p.activate(1.0, flying=True, fresh=True) is Do.ADVANCE
    assert p.activate(2.0, flying=True, fresh=False) is Do.NOTHING
    assert p.activate(3.0, flying=False, fresh=True) is Do.NOTHING
    assert made == []


def test_a_refused_priority_is_reported_once_and_not_asked_again():
    p, made, _ = pacing(tick_priority=10)
    p.start_episode(1, wait=False, active=True, now=0.0)
    made[0].priority_error = "SCHED_FIFO 10 refused: [Errno 1] Operation not permitted"
    assert p.priority_refused(made[0]).startswith("SCHED_FIFO 10 refused")
    assert p.priority_refused(made[0]) is None
    p.start_episode(2, wait=False, active=True, now=1.0)
    assert (made[0].priority, made[1].priority) == (10, 0)


def test_take_ticker_hands_the_clock_over_once():
    p, made, _ = pacing()
    p.start_episode(1, wait=False, active=True, now=0.0)
    assert p.take_ticker() is made[0]
    assert p.take_ticker() is None and not made[0].stopped  # the caller stops and joins it


# ---------------------------------------------------------------------- the reset gate
def test_reset_gate_accepts_an_active_node_s_reset_for_itself_or_for_no_one():
    g = ResetGate("a1")
    assert g.judge("", "", 100.0, lambda: []) == (None, 0.0)
    assert g.judge("", "a1", 100.0, lambda: []) == (None, 0.0)


def test_reset_gate_refuses_while_not_active_at_once():
    why, delay = ResetGate("a1").judge("pd_sim_node is inactive", "a1", 0.0, lambda: [])
    assert (why, delay) == ("reset refused: pd_sim_node is inactive", 0.0)


def test_reset_gate_refuses_another_lander_s_reset_late():
    why, delay = ResetGate("a1").judge("", "b2", 0.0, lambda: [])
    assert why == "reset refused: it is for lander 'b2', this is 'a1'"
    assert delay == REFUSE_DELAY_S == 1.0


def test_reset_gate_refuses_an_unnamed_reset_for_5_s_after_another_lander_s_command():
    g = ResetGate("a1")
    assert not g.command(None, "c3", 99.0)  # accepted: not foreign
    assert not g.command("stale", "c3", 99.0)
    assert not g.command("foreign", "", 99.0)  # command_source: not another lander
    assert not g.command("foreign", "a1", 99.0)
    assert g.foreign_at == -math.inf
    assert g.command("foreign", "c3", 100.0)
    assert g.foreign_at == 100.0
    why, delay = g.judge("", "", 100.0 + AMBIGUOUS_S - 0.1, lambda: ["c3", "b2"])
    assert why == (
        "reset refused: ambiguous, lander 'a1' shares its names with b2, c3; name the lander "
        "(ResetEpisode.lander_id)"
    )
    assert delay == 0.0
    assert g.judge("", "a1", 101.0, lambda: ["c3"]) == (None, 0.0)  # named: not ambiguous
    assert g.judge("", "", 100.0 + AMBIGUOUS_S, lambda: ["c3"]) == (None, 0.0)


def test_reset_gate_asks_for_the_other_landers_only_when_ambiguous():
    asked = []
    ResetGate("a1").judge("", "", 0.0, lambda: asked.append(1) or [])
    assert asked == []
