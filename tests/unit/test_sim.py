"""pd_core.sim: command validation, episode bookkeeping, equivalence with the env, the ticker."""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
import pytest

from pd_core.actions import DEFAULT_ACTIONS
from pd_core.config import DT_S, GRAVITY_MPS2
from pd_core.env import PoweredDescentEnv
from pd_core.lander import Status
from pd_core.sim import Command, Simulator, check_command, describe_end
from pd_core.ticker import FixedRateTicker, percentiles_ms

TABLE = DEFAULT_ACTIONS.table_n
HOVER = int(DEFAULT_ACTIONS.levels_to_action(np.array([3, 3, 2])))  # 0, 0, 13 kN


def cmd(episode: int, step: int, action: int, thrust=None) -> Command:
    t = TABLE[action] if thrust is None else thrust
    return Command(episode, step, action, tuple(float(v) for v in t))


def test_check_command_accepts_valid():
    assert check_command(cmd(1, 4, 10), 1, 4) is None


@pytest.mark.parametrize("action", [-1, 147, 1000, 2.5, None, True])
def test_check_command_rejects_unknown_action(action):
    c = Command(1, 0, action, (0.0, 0.0, 0.0))
    kind, msg = check_command(c, 1, 0)
    assert kind == "action"
    assert "unknown action" in msg


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_check_command_rejects_non_finite_thrust(bad):
    kind, msg = check_command(cmd(1, 0, 5, (bad, 0.0, 0.0)), 1, 0)
    assert kind == "thrust"
    assert "NaN or infinite" in msg


def test_check_command_rejects_thrust_not_matching_action():
    t = TABLE[5].copy()
    t[2] += 1.0
    kind, msg = check_command(cmd(1, 0, 5, t), 1, 0)
    assert kind == "thrust"
    assert "does not match action 5" in msg


def test_check_command_timing():
    assert check_command(cmd(1, 3, 0), 1, 4)[0] == "stale"
    assert check_command(cmd(0, 9, 0), 1, 0)[0] == "stale"
    assert check_command(cmd(1, 5, 0), 1, 4)[0] == "ahead"
    assert check_command(cmd(1, 5, 0), None, None)[0] == "idle"
    # content is judged before timing
    assert check_command(cmd(1, 3, 0, (np.nan, 0, 0)), 1, 4)[0] == "thrust"


def test_reset_numbers_episodes_and_uses_given_state():
    sim = Simulator(seed=3)
    s0 = np.array([500.0, 20.0, 2500.0, -10.0, 5.0, -80.0, 2000.0])
    ep, init, interrupted = sim.reset(initial_state=s0)
    assert (ep, sim.step, sim.flying, interrupted) == (1, 0, True, None)
    np.testing.assert_array_equal(init, s0)
    ep2, init2, interrupted = sim.reset()
    assert ep2 == 2
    assert interrupted is not None and interrupted["status"] == int(Status.FLYING)
    assert "interrupted" in interrupted["reason"]
    assert not np.array_equal(init2, s0)


def test_reset_rejects_bad_state_and_keeps_episode():
    sim = Simulator(seed=1)
    sim.reset()
    sim.submit(cmd(1, 0, HOVER))
    sim.advance()
    with pytest.raises(ValueError, match="NaN"):
        sim.reset(initial_state=[np.nan] * 7)
    with pytest.raises(ValueError, match="mass"):
        sim.reset(initial_state=[0, 0, 100, 0, 0, 0, -1])
    assert (sim.episode, sim.step, sim.flying) == (1, 1, True)


def test_same_seed_same_initial_state_as_env():
    sim = Simulator()
    _, init, _ = sim.reset(seed=42)
    _, info = PoweredDescentEnv().reset(seed=42)
    np.testing.assert_array_equal(init, info["state"])


def _fly_env(seed, s0, actions):
    env = PoweredDescentEnv()
    env.reset(seed=seed, options={"initial_state": s0})
    for a in actions:
        _, _, term, trunc, info = env.step(a)
        if term or trunc:
            break
    return info


def test_flying_commands_matches_env_bit_for_bit():
    rng = np.random.default_rng(0)
    s0 = np.array([800.0, -300.0, 2450.0, -40.0, 10.0, -80.0, 2000.0])
    acts = [int(a) for a in rng.integers(0, 147, size=400)]
    sim = Simulator()
    sim.reset(initial_state=s0, seed=7)
    for a in acts:
        assert sim.submit(cmd(sim.episode, sim.step, a)) is None
        assert sim.has_fresh_command
        out = sim.advance()
        assert out.fresh and out.action == a
        if out.done:
            break
    info = _fly_env(7, s0, acts)
    np.testing.assert_array_equal(sim.state, info["state"])
    assert out.result["status"] == info["status"]
    assert out.result["steps"] == sim.step


def test_rejected_commands_are_counted_and_never_applied():
    sim = Simulator(missing_command="zero")
    sim.reset(seed=5)
    twin = Simulator(missing_command="zero")
    twin.reset(seed=5)
    sim.submit(cmd(1, 0, HOVER))
    sim.advance()
    twin.submit(cmd(1, 0, HOVER))
    twin.advance()
    bad = [
        Command(1, 1, 999, (0.0, 0.0, 0.0)),  # unknown action
        cmd(1, 1, 3, (np.nan, 0.0, 0.0)),  # NaN thrust
        cmd(1, 0, 3),  # stale step
        cmd(0, 1, 3),  # stale episode
        cmd(1, 2, 3),  # ahead
    ]
    for c in bad:
        assert sim.submit(c) is not None
    assert not sim.has_fresh_command
    out = sim.advance()
    assert not out.fresh
    twin.advance()  # zero thrust on both
    np.testing.assert_array_equal(sim.state, twin.state)
    assert sim.counters.rejected_commands == 5
    assert sim.counters.rejected_by_reason == {"action": 1, "thrust": 1, "stale": 2, "ahead": 1}
    result = sim.reset()[2]
    assert result["rejected_commands"] == 5
    assert result["missed_commands"] == 1


def test_first_valid_command_wins_later_ones_rejected_and_counted():
    sim = Simulator()
    sim.reset(seed=0)
    assert sim.submit(cmd(1, 0, 3)) is None
    kind, why = sim.submit(cmd(1, 0, HOVER))
    assert kind == "conflict" and "first command wins" in why and f"action {HOVER}" in why
    assert sim.submit(cmd(1, 0, 3))[0] == "duplicate"
    assert sim.advance().action == 3
    assert sim.counters.rejected_by_reason == {"conflict": 1, "duplicate": 1}
    # an invalid command never blocks the valid one that follows it
    assert sim.submit(cmd(1, 1, 500, (0.0, 0.0, 0.0)))[0] == "action"
    assert sim.submit(cmd(1, 1, HOVER)) is None
    assert sim.advance().action == HOVER
    assert sim.reset()[2]["rejected_commands"] == 3


def test_with_a_command_source_a_foreign_command_never_flies_even_first():
    sim = Simulator(command_source="pd_policy_node")
    sim.reset(seed=0)
    stray = replace(cmd(1, 0, 3), source="stray_node")
    kind, why = sim.submit(stray)
    assert kind == "foreign" and "'stray_node'" in why and "command_source" in why
    assert sim.submit(replace(cmd(1, 0, HOVER), source=""))[0] == "foreign"  # unresolved
    assert sim.submit(replace(cmd(1, 0, HOVER), source="pd_policy_node")) is None
    assert sim.advance().action == HOVER
    # foreign is checked before content: a malformed stray is reported as foreign
    bad = replace(cmd(1, 1, 500, (0.0, 0.0, 0.0)), source="stray_node")
    assert sim.submit(bad)[0] == "foreign"
    assert sim.counters.rejected_by_reason == {"foreign": 3}
    assert sim.reset()[2]["rejected_commands"] == 3
    anyone = Simulator()  # default: any publisher, first command wins
    anyone.reset(seed=0)
    assert anyone.submit(stray) is None


@pytest.mark.parametrize(
    ("state", "says"),
    [
        ([0, 0, 0.0, 0, 0, -10, 1900], "altitude"),
        ([0, 0, -100.0, 0, 0, -10, 1900], "altitude"),
        ([0, 0, 1500, 0, 0, -10, 500.0], "dry mass"),
        ([0, 0, 1500, 0, 0, -10, 1000.0], "dry mass"),
        ([0, 0, 1500, 0, 0], "7 entries"),
    ],
)
def test_reset_refuses_states_the_lander_cannot_fly_from(state, says):
    sim = Simulator(seed=1)
    sim.reset()
    with pytest.raises(ValueError, match=says):
        sim.reset(initial_state=state)
    assert (sim.episode, sim.flying) == (1, True)


@pytest.mark.parametrize(("mode", "expected"), [("hold", HOVER), ("zero", None)])
def test_missing_command_hold_or_zero(mode, expected):
    sim = Simulator(missing_command=mode)
    sim.reset(seed=0)
    first = sim.advance()  # nothing to hold yet: zero thrust
    assert (first.action, first.thrust_n, first.fresh) == (None, (0.0, 0.0, 0.0), False)
    sim.submit(cmd(1, 1, HOVER))
    assert sim.advance().action == HOVER
    out = sim.advance()
    assert out.action == expected and not out.fresh
    if expected is None:
        assert out.thrust_n == (0.0, 0.0, 0.0)
    assert sim.counters.missed_commands == 2


def test_an_actuation_delay_flies_each_command_that_many_steps_late():
    """delay_steps 2: zero thrust for the first two steps of an episode (engines not lit), then
    the command of two steps earlier; a reset refills the FIFO with zero thrust."""
    levels = [np.array(v) for v in ([3, 3, 2], [6, 3, 1], [0, 6, 2], [3, 0, 0])]
    acts = [int(DEFAULT_ACTIONS.levels_to_action(v)) for v in levels]
    sim = Simulator(disturbance=False, delay_steps=2)
    for _ in range(2):
        ep, _, _ = sim.reset(initial_state=[0.0, 0.0, 1500.0, 0.0, 0.0, -50.0, 2000.0])
        flown = []
        for k, a in enumerate(acts):
            sim.submit(cmd(ep, k, a))
            out = sim.advance()
            assert out.action == a and out.fresh
            flown.append(out.thrust_n)
        zero = (0.0, 0.0, 0.0)
        want = [zero, zero] + [tuple(DEFAULT_ACTIONS.table_n[a]) for a in acts[:2]]
        assert flown == want
    for bad in (-1, 51, 1.5):
        with pytest.raises(ValueError, match="delay_steps must be an integer in"):
            Simulator(delay_steps=bad)


def test_navigation_noise_is_white_on_position_and_velocity_and_repeats_with_the_seed():
    """nav_sigma (3 m, 0.3 m/s): the published state is the true one plus noise of that spread
    (within 15 % over 300 steps x 3 axes), none on the mass; the same seed, the same noise; the
    flight itself (true state) does not depend on it."""

    def fly(sigma):
        sim = Simulator(nav_sigma=sigma)
        ep, _, _ = sim.reset(seed=5)
        err, true = [], []
        for k in range(300):
            err.append(sim.observed_state - sim.state)
            true.append(sim.state.copy())
            sim.submit(cmd(ep, k, int(DEFAULT_ACTIONS.levels_to_action(np.array([3, 3, 1])))))
            if sim.advance().done:
                break
        return np.array(err), np.array(true)

    err, true = fly((3.0, 0.3))
    np.testing.assert_allclose(err[:, 0:3].std(), 3.0, rtol=0.15)
    np.testing.assert_allclose(err[:, 3:6].std(), 0.3, rtol=0.15)
    assert not err[:, 6].any()
    np.testing.assert_array_equal(fly((3.0, 0.3))[0], err)
    quiet, true0 = fly((0.0, 0.0))
    assert not quiet.any()
    np.testing.assert_array_equal(true0, true)
    for bad in ((-1.0, 0.0), (0.0, float("nan")), (51.0, 0.0)):
        with pytest.raises(ValueError, match="navigation noise must be in"):
            Simulator(nav_sigma=bad)


def test_an_engine_out_of_spec_delivers_that_fraction_of_every_command():
    """thrust_scale 0.85: one step of full thrust on every axis changes the velocity by 0.85 of
    what the nominal engine gives (the thrust over the mean mass of the step, no disturbance),
    and burns 0.85 of its fuel; out-of-range scales are refused in one line."""
    full = int(DEFAULT_ACTIONS.levels_to_action(np.array([6, 6, 2])))
    dv, fuel = {}, {}
    for scale in (1.0, 0.85):
        sim = Simulator(disturbance=False, thrust_scale=scale)
        ep, s0, _ = sim.reset(initial_state=[0.0, 0.0, 1500.0, 0.0, 0.0, -50.0, 2000.0])
        sim.submit(cmd(ep, 0, full))
        out = sim.advance()
        assert out.thrust_n == pytest.approx(tuple(scale * DEFAULT_ACTIONS.table_n[full]))
        dv[scale] = sim.state[3:6] - s0[3:6] - GRAVITY_MPS2 * DT_S
        fuel[scale] = s0[6] - sim.state[6]
    np.testing.assert_allclose(dv[0.85], 0.85 * dv[1.0], rtol=2e-3)
    assert fuel[0.85] == pytest.approx(0.85 * fuel[1.0], rel=1e-9)
    for bad in (0.4, 1.6, float("nan")):
        with pytest.raises(ValueError, match="thrust_scale must be in"):
            Simulator(thrust_scale=bad)


def test_free_fall_crashes_with_reason_and_stops():
    sim = Simulator(disturbance=False)
    sim.reset(initial_state=[0.0, 0.0, 50.0, 0.0, 0.0, -20.0, 2000.0])
    while True:
        out = sim.advance()
        if out.done:
            break
    r = out.result
    assert out.status == Status.CRASHED and not r["landed"]
    assert r["status"] == int(Status.CRASHED)
    assert "too fast" in r["reason"]
    assert r["fuel"] == 0.0 and r["missed_commands"] == r["steps"]
    assert not sim.flying
    assert sim.submit(cmd(1, sim.step, 0))[0] == "idle"
    with pytest.raises(RuntimeError):
        sim.advance()


def test_out_of_time_is_reported():
    sim = Simulator(max_time_s=1.0)
    sim.reset(seed=2)
    outs = [sim.advance() for _ in range(5)]
    assert [o.done for o in outs] == [False] * 4 + [True]
    assert outs[-1].status == Status.OUT_OF_TIME
    assert outs[-1].result["reason"].startswith("out of time")


def test_describe_end_landed():
    text = describe_end(Status.LANDED, np.array([0.5, 0, 0.0, 0, 0, -1.0, 1600]), 60.0)
    assert text.startswith("landed")


def test_bad_constructor_arguments():
    with pytest.raises(ValueError, match="missing_command"):
        Simulator(missing_command="last")
    with pytest.raises(ValueError, match="max_time_s"):
        Simulator(max_time_s=0.0)


def test_ticker_keeps_rate_without_drift():
    ticks: list[float] = []
    ticker = FixedRateTicker(0.02, lambda: ticks.append(time.monotonic()))
    t0 = time.monotonic()
    ticker.start()
    time.sleep(0.5)
    ticker.stop()
    elapsed = time.monotonic() - t0  # the sleep may overrun on a loaded machine
    assert ticker.error is None
    periods = np.diff(ticks)
    assert 20 <= len(ticks) <= elapsed / 0.02 + 1
    # drift-free: the mean period is the nominal one even if single wake-ups are late
    assert abs((ticks[-1] - ticks[0]) / (len(ticks) - 1) - 0.02) < 0.002
    assert np.all(periods > 0)


def test_ticker_skips_missed_deadlines_and_keeps_errors():
    calls = []

    def slow():
        calls.append(1)
        if len(calls) == 1:
            time.sleep(0.055)
        if len(calls) == 3:
            raise RuntimeError("boom")

    ticker = FixedRateTicker(0.02, slow)
    ticker.start()
    time.sleep(0.2)
    ticker.stop()
    assert ticker.skipped >= 2
    assert isinstance(ticker.error, RuntimeError)
    assert len(calls) == 3


def test_percentiles_ms():
    p = percentiles_ms([0.001, 0.002, 0.003])
    assert p["n"] == 3 and p["p50"] == pytest.approx(2.0) and p["max"] == pytest.approx(3.0)
    assert percentiles_ms([])["n"] == 0
    with pytest.raises(ValueError):
        FixedRateTicker(0.0, lambda: None)
