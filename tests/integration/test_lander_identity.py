"""Commands carry the identity of the lander they answer (issue 33, item 3).

- without processes: pd_core's Simulator counts a command for another lander as foreign (not
  rejected, never flown, even when it answers the current step); the message conversion echoes
  the state's lander_id; the diagnostics rules pick the worst level;
- two whole stacks (simulator and policy each, real time) on one domain without namespaces: each
  lander flies only commands that name it; each simulator counts the other's as foreign, logs one
  error line naming the other lander and reports ERROR on /diagnostics; each policy says there
  is a second lander; a reset naming no lander is refused as ambiguous, one naming a lander
  resets that lander only.
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from helpers import ProcessSet

from pd_core.commands import Command
from pd_core.sim import Simulator
from pd_interfaces.msg import EpisodeResult, LanderState, ThrustCommand
from pd_ros_common import clients, diagnostics, names, qos
from pd_ros_common.convert import command_msg, guidance_msg, reset_request, state_msg

START_S = 90.0  # node start-up deadline on a loaded 2-core machine (torch import)
HOVER = 70  # any valid action


def _cmd(sim: Simulator, lander_id: str) -> Command:
    thrust = tuple(float(v) for v in sim.actions.table_n[HOVER])
    return Command(sim.episode, sim.step, HOVER, thrust, "", lander_id)


def test_simulator_counts_commands_for_another_lander_as_foreign():
    sim = Simulator(seed=0, lander_id="alpha")
    sim.reset()
    kind, why = sim.submit(_cmd(sim, "bravo"))  # answers the current step, first: not flown
    assert kind == "foreign" and "'bravo'" in why and "'alpha'" in why
    assert not sim.has_fresh_command
    assert sim.counters.foreign_commands == 1 and sim.counters.rejected_commands == 0
    assert sim.counters.foreign_by_lander == {"bravo": 1}
    assert sim.submit(_cmd(sim, "alpha")) is None  # its own lander's command flies
    assert sim.submit(_cmd(sim, "")) is not None  # (an unaddressed one is judged as before:
    assert sim.counters.rejected_by_reason == {"duplicate": 1}  # the step is answered)
    sim.advance()
    sim.submit(_cmd(sim, "bravo"))
    result = sim.reset()[2]
    assert result["foreign_commands"] == 2 and result["lander_id"] == "alpha"


def test_policy_messages_echo_the_state_lander_id():
    from pd_core.runtime.decision import Decision

    state = state_msg(1, 5, 1.0, np.full(7, 100.0), LanderState.FLYING, "alpha")
    assert state.lander_id == "alpha" and state.header.frame_id == "landing_site"
    cmd = command_msg(state, HOVER, np.zeros(3))
    assert (cmd.lander_id, cmd.episode, cmd.step, cmd.header) == ("alpha", 1, 5, state.header)
    d = Decision(HOVER, HOVER, "network", 0, 1.0, False)
    assert guidance_msg(state, d, 0.001).lander_id == "alpha"


def test_diagnostics_report_takes_the_worst_rule():
    r = diagnostics.Report(ok_message="fine")
    assert (r.level, r.message) == (diagnostics.OK, "fine")
    r.rule(diagnostics.WARN, True, "slow").rule(diagnostics.ERROR, True, "two landers")
    r.rule(diagnostics.ERROR, False, "never")
    assert (r.level, r.message) == (diagnostics.ERROR, "two landers; slow")
    r.values = {"rate": 4.99999999, "flying": True, "ids": ["a", "b"]}
    s = diagnostics.status("pd_sim_node: simulator", r, "alpha")
    assert diagnostics.level_of(s) == diagnostics.ERROR and s.hardware_id == "alpha"
    assert diagnostics.values_of(s) == {"rate": "5", "flying": "true", "ids": "a, b"}
    since = diagnostics.Since()
    assert since(n=3) == {"n": 3} and since(n=5) == {"n": 2}


@pytest.mark.integration
@pytest.mark.slow
@pytest.mark.timeout(400)
def test_two_stacks_without_namespaces_fly_only_their_own_commands(
    tmp_path, make_node, spin_until, service_ready
):
    procs = ProcessSet(tmp_path)
    probe = make_node("identity_probe")
    states: list[LanderState] = []
    commands: list[ThrustCommand] = []
    results: list[EpisodeResult] = []
    statuses: dict[str, list] = {}

    def on_diagnostics(msg: DiagnosticArray) -> None:
        for s in msg.status:
            statuses.setdefault(s.name, []).append(s)

    probe.create_subscription(LanderState, "/lander/state", states.append, qos.LOOP_SUB_QOS)
    probe.create_subscription(
        ThrustCommand, "/lander/thrust_cmd", commands.append, qos.LOOP_SUB_QOS
    )
    probe.create_subscription(EpisodeResult, "/lander/episode", results.append, qos.EPISODE_QOS)
    probe.create_subscription(
        DiagnosticArray, names.DIAGNOSTICS_TOPIC, on_diagnostics, qos.DIAGNOSTICS_QOS
    )
    sim_params = {"rate_hz": 10.0, "max_time_s": 40.0, "log_rejections": 10000}
    try:
        # "alpha" named; the other one random, as a forgotten second launch would be
        sim_a = procs.node(
            "pd_sim_node", {**sim_params, "seed": 1, "lander_id": "alpha"}, name="sim_alpha"
        )
        sim_b = procs.node("pd_sim_node", {**sim_params, "seed": 2}, name="sim_other")
        pol_a = procs.node("pd_policy_node", {}, name="policy_a")
        pol_b = procs.node("pd_policy_node", {}, name="policy_b")
        assert sim_b.wait_log("simulator ready", START_S), procs.logs()
        other = re.search(r"lander_id=(\w+)", sim_b.log()).group(1)
        assert other != "alpha"

        # Both simulators hear the other's commands: counted as foreign, at ERROR. (Both
        # stacks have the same node names, as a second launch would: told apart by lander.)
        def at_error(lander: str) -> bool:
            sims = statuses.get("pd_sim_node: simulator", [])
            return any(
                diagnostics.level_of(s) == diagnostics.ERROR and s.hardware_id == lander
                for s in sims
            )

        def policy_error() -> bool:
            pols = statuses.get("pd_policy_node: policy", [])
            return any(diagnostics.level_of(s) == diagnostics.ERROR for s in pols)

        assert spin_until(
            lambda: at_error("alpha") and at_error(other) and policy_error(), START_S
        ), (procs.logs(), statuses)

        # A reset naming no lander is ambiguous now: refused (by whichever answers).
        reset = clients.reset_client(probe)
        assert service_ready(reset, 30.0)
        future = reset.call_async(reset_request(None, seed=5))
        assert spin_until(future.done, 30.0), procs.logs()
        assert not future.result().success and "ambiguous" in future.result().message
        # One naming alpha resets alpha only (the other refuses, later).
        future = reset.call_async(reset_request(None, seed=5, lander_id="alpha"))
        assert spin_until(future.done, 30.0), procs.logs()
        assert future.result().success, future.result().message
        assert future.result().lander_id == "alpha" and future.result().episode == 2

        def ended(lander: str, episode: int) -> bool:
            return any(r.lander_id == lander and r.episode == episode for r in results)

        assert spin_until(
            lambda: ended("alpha", 1) and ended("alpha", 2) and ended(other, 1), 240.0
        ), procs.logs()
        assert all(p.alive for p in (sim_a, sim_b, pol_a, pol_b)), procs.logs()
    finally:
        procs.stop_all()

    first = {r.lander_id: r for r in results if r.episode == 1}
    assert first["alpha"].foreign_commands > 0 and first[other].foreign_commands > 0, results
    assert "interrupted" in first["alpha"].reason  # alpha was reset; the other flew on
    assert not any(r.lander_id == other and r.episode == 2 for r in results), results
    # Each simulator said it once, naming the other lander; foreign commands are not rejected.
    for log, me, them in ((sim_a.log(), "alpha", other), (sim_b.log(), other, "alpha")):
        lines = [ln for ln in log.splitlines() if "commands for lander" in ln]
        assert len(lines) == 1, lines
        assert f"'{them}'" in lines[0] and f"this is lander '{me}'" in lines[0], lines
        assert "command rejected (foreign)" not in log
    assert "reset refused: ambiguous" in sim_a.log() + sim_b.log()
    assert f"reset refused: it is for lander 'alpha', this is '{other}'" in sim_b.log()
    # Each policy answered both, each with the id of the state it answered, and said so.
    for pol in (pol_a, pol_b):
        assert "states of lander" in pol.log() and "second simulator" in pol.log(), pol.log()

    # This probe is the slow reader on a loaded machine: a command's state may still sit in its
    # state queue when the stacks stop (another topic, another queue). Let it take them off. The
    # probe may also discover a simulator later than that simulator's policy does (volatile QoS):
    # commands answering states published before the probe first heard that lander's episode
    # are left out, not counted against it.
    def checked() -> list[ThrustCommand]:
        first: dict[tuple[str, int], int] = {}
        for s in states:
            key = (s.lander_id, s.episode)
            first[key] = min(first.get(key, s.step), s.step)
        return [c for c in commands if c.step >= first.get((c.lander_id, c.episode), c.step + 1)]

    def answered_states_heard() -> bool:
        heard = {(s.lander_id, s.episode, s.step) for s in states}
        return all((c.lander_id, c.episode, c.step) in heard for c in checked())

    spin_until(answered_states_heard, 20.0)
    seen = {(s.lander_id, s.episode, s.step) for s in states}
    assert {c.lander_id for c in commands} == {"alpha", other}
    assert len(checked()) > 0.9 * len(commands), (len(checked()), len(commands))
    assert all((c.lander_id, c.episode, c.step) in seen for c in checked())
