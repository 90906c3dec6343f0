"""Managed (lifecycle) nodes over DDS, as real processes, driven by a plain `lifecycle_msgs`
client (issue 71):

- each node through every transition, and invalid transitions refused without killing it;
- an inactive simulator publishes no state; an inactive policy publishes no command while
  states arrive; an inactive OCP node answers success=false "inactive";
- deactivate and activate in mid-flight (simulator and policy, real time): the episode lands,
  no step lost or flown twice;
- the lifecycle manager brings the stack up and down (Ctrl-C, reverse order), and takes it down
  when one node is killed;
- the simulator's old episode `autostart:=false` still works, as a deprecated alias.

The policy flies the ZEM/ZEV reference controller (no torch: a quick start-up).
"""

from __future__ import annotations

import signal
import subprocess

import pytest
from helpers import LoopListener, ProcessSet, executable
from lifecycle_msgs.msg import State, Transition
from lifecycle_msgs.srv import ChangeState, GetAvailableStates, GetAvailableTransitions, GetState

from pd_core import lifecycle as lc
from pd_interfaces.srv import ComputeTrajectory, ResetEpisode
from pd_ros_common import diagnostics
from pd_ros_common.convert import reset_request

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.timeout(300)]

START_S = 90.0  # node start-up on a loaded 2-core machine
CALL_S = 30.0  # a transition (configure loads a policy, starts a solver process)
SIM = {"lockstep": True, "autostart": False, "start_episode": True, "resend_s": 0.5, "seed": 3}
POLICY = {"controller": "zemzev", "autostart": False}
QUIET_S = 2.0  # a window four resend periods long in which an inactive node must stay silent


class Lifecycle:
    """A plain lifecycle_msgs client of one node: change_state, get_state and the lists."""

    def __init__(self, node, spin_until, target: str) -> None:
        self.spin_until = spin_until
        self.change_cli = node.create_client(ChangeState, f"/{target}/change_state")
        self.state_cli = node.create_client(GetState, f"/{target}/get_state")
        self.states_cli = node.create_client(GetAvailableStates, f"/{target}/get_available_states")
        self.transitions_cli = node.create_client(
            GetAvailableTransitions, f"/{target}/get_available_transitions"
        )

    def ready(self) -> bool:
        return all(
            c.service_is_ready()
            for c in (self.change_cli, self.state_cli, self.states_cli, self.transitions_cli)
        )

    def call(self, client, request):
        future = client.call_async(request)
        assert self.spin_until(future.done, CALL_S), f"{client.srv_name}: no answer"
        return future.result()

    def state(self) -> str:
        return self.call(self.state_cli, GetState.Request()).current_state.label

    def change(self, transition_id: int = 0, label: str = "") -> bool:
        request = ChangeState.Request(transition=Transition(id=transition_id, label=label))
        return self.call(self.change_cli, request).success

    def available_states(self) -> set[str]:
        resp = self.call(self.states_cli, GetAvailableStates.Request())
        return {s.label for s in resp.available_states}

    def available_transitions(self) -> set[str]:
        resp = self.call(self.transitions_cli, GetAvailableTransitions.Request())
        return {t.transition.label for t in resp.available_transitions}


class Probe:
    """States, commands and results heard; a lifecycle client per node; the reset client."""

    def __init__(self, make_node, spin_until, service_ready, targets: list[str]) -> None:
        self.node = make_node("lifecycle_probe")
        self.spin_until = spin_until
        heard = LoopListener(self.node)
        self.states, self.commands, self.results = heard.states, heard.commands, heard.results
        self.diagnostics = diagnostics.Listener(self.node)
        self.lc = {t: Lifecycle(self.node, spin_until, t) for t in targets}
        for t, c in self.lc.items():
            assert service_ready(c.change_cli, START_S), f"{t}: no change_state"
            assert spin_until(c.ready, START_S), f"{t}: lifecycle services missing"

    def go(self, target: str, *transitions: int) -> str:
        for t in transitions:
            assert self.lc[target].change(t), f"{target}: transition {t} refused"
        return self.lc[target].state()

    def quiet(self, count, tries: int = 3) -> bool:
        """True once `count()` stays the same for QUIET_S (spinning meanwhile), within `tries`
        windows: a message sent before the transition may still be on its way at first."""
        for _ in range(tries):
            before = count()
            if not self.spin_until(lambda before=before: count() > before, QUIET_S):
                return True
        return False

    def steps(self, episode: int) -> list[int]:
        return [s.step for s in self.states if s.episode == episode]


T = Transition


def test_every_node_goes_through_every_transition_and_survives_invalid_ones(
    tmp_path, make_node, spin_until, service_ready
):
    procs = ProcessSet(tmp_path)
    try:
        sim = procs.node("pd_sim_node", SIM)
        pol = procs.node("pd_policy_node", POLICY)
        ocp = procs.node("pd_ocp_node", {"autostart": False})
        names = ["pd_sim_node", "pd_policy_node", "pd_ocp_node"]
        probe = Probe(make_node, spin_until, service_ready, names)
        for name, child in zip(names, (sim, pol, ocp), strict=True):
            lc = probe.lc[name]
            assert lc.state() == "unconfigured"
            assert {"unconfigured", "inactive", "active", "finalized"} <= lc.available_states()
            assert lc.available_transitions() == {"configure", "shutdown"}
            # invalid transitions: answered false, logged, the node lives on in its state
            assert not lc.change(T.TRANSITION_ACTIVATE)
            assert not lc.change(99)
            assert not lc.change(label="bogus")
            assert lc.state() == "unconfigured" and child.alive
            assert probe.go(name, T.TRANSITION_CONFIGURE) == "inactive"
            assert not lc.change(T.TRANSITION_CONFIGURE)
            assert probe.go(name, T.TRANSITION_ACTIVATE) == "active"
            assert not lc.change(T.TRANSITION_CLEANUP)
            assert probe.go(name, T.TRANSITION_DEACTIVATE) == "inactive"
            assert probe.go(name, T.TRANSITION_CLEANUP) == "unconfigured"
            assert probe.go(name, T.TRANSITION_CONFIGURE, T.TRANSITION_ACTIVATE) == "active"
            assert probe.go(name, T.TRANSITION_DEACTIVATE) == "inactive"
            assert lc.change(label="shutdown") and lc.state() == "finalized"
            assert not lc.change(T.TRANSITION_CONFIGURE) and lc.state() == "finalized"
            assert child.alive, child.log()
            log = child.log()
            assert "transition 'activate' refused in state unconfigured" in log, log
            assert "unknown transition '99' refused" in log and "'bogus' refused" in log
            assert "cleaned up: " in log and "shut down from inactive" in log
        assert "policy released" in pol.log() and "solver process stopped" in ocp.log()
    finally:
        procs.stop_all()
    for child in (sim, pol, ocp):
        assert child.proc.returncode == 0, child.log()
        assert "Traceback" not in child.log(), child.log()


def test_inactive_nodes_publish_nothing_and_refuse_work(
    tmp_path, make_node, spin_until, service_ready
):
    procs = ProcessSet(tmp_path)
    try:
        procs.node("pd_sim_node", SIM)
        procs.node("pd_policy_node", POLICY)
        procs.node("pd_ocp_node", {"autostart": False})
        probe = Probe(
            make_node, spin_until, service_ready, ["pd_sim_node", "pd_policy_node", "pd_ocp_node"]
        )
        for name in probe.lc:
            assert probe.go(name, T.TRANSITION_CONFIGURE) == "inactive"
        # configured, inactive: the first episode exists, no state goes out
        assert probe.quiet(lambda: len(probe.states))
        # /diagnostics keeps answering, with the lifecycle state
        assert spin_until(
            lambda: (
                probe.diagnostics.values("pd_sim_node: simulator").get("lifecycle state")
                == "inactive"
            ),
            10.0,
        )
        # the OCP answers "inactive"; the simulator refuses resets
        ocp_cli = probe.node.create_client(ComputeTrajectory, "/ocp/compute_trajectory")
        assert service_ready(ocp_cli)
        answer = probe.lc["pd_ocp_node"].call(ocp_cli, ComputeTrajectory.Request())
        assert not answer.success and "inactive" in answer.message, answer.message
        reset_cli = probe.node.create_client(ResetEpisode, "/sim/reset")
        assert service_ready(reset_cli)
        answer = probe.lc["pd_sim_node"].call(reset_cli, reset_request(None, 1))
        assert not answer.success and "inactive" in answer.message, answer.message

        # the simulator active, the policy inactive: states (resent) arrive, no command
        assert probe.go("pd_sim_node", T.TRANSITION_ACTIVATE) == "active"
        assert spin_until(lambda: len(probe.states) >= 4, 20.0)
        assert {s.step for s in probe.states} == {0}
        assert probe.commands == []
        assert probe.quiet(lambda: len(probe.commands))

        # the simulator inactive again: not one state more
        assert probe.go("pd_sim_node", T.TRANSITION_DEACTIVATE) == "inactive"
        assert probe.quiet(lambda: len(probe.states))
    finally:
        procs.stop_all()


def test_deactivate_and_activate_in_mid_flight_lose_no_step(
    tmp_path, make_node, spin_until, service_ready
):
    """Real time (20 Hz here; a lockstep episode flies in a tenth of a second): the simulator
    held mid-flight stops its clock, then the policy is held too and nothing is answered;
    both active again (policy first, as the manager orders them), the episode goes on from
    the step held, a full period later, and lands with every step flown once, on its command."""
    procs = ProcessSet(tmp_path)
    try:
        sim = procs.node("pd_sim_node", {**SIM, "lockstep": False, "rate_hz": 20.0})
        procs.node("pd_policy_node", POLICY)
        probe = Probe(make_node, spin_until, service_ready, ["pd_policy_node", "pd_sim_node"])
        for name in ("pd_policy_node", "pd_sim_node"):
            assert probe.go(name, T.TRANSITION_CONFIGURE, T.TRANSITION_ACTIVATE) == "active"
        assert spin_until(lambda: len(probe.commands) >= 40, 60.0)
        assert probe.go("pd_sim_node", T.TRANSITION_DEACTIVATE) == "inactive"
        assert probe.quiet(lambda: len(probe.states))
        held = probe.states[-1].step  # the last state published: the step the node holds
        assert probe.go("pd_policy_node", T.TRANSITION_DEACTIVATE) == "inactive"
        answered = len(probe.commands)
        assert probe.quiet(lambda: len(probe.commands)) and len(probe.commands) == answered
        assert probe.go("pd_policy_node", T.TRANSITION_ACTIVATE) == "active"
        assert probe.go("pd_sim_node", T.TRANSITION_ACTIVATE) == "active"
        assert spin_until(lambda: probe.results, 120.0), sim.log()
        result = probe.results[0]
        assert result.landed, result.reason
        steps = sorted(set(probe.steps(result.episode)))
        assert steps == list(range(result.steps + 1)) and held < result.steps
        commanded = [c.step for c in probe.commands if c.episode == result.episode]
        assert sorted(commanded) == list(range(result.steps))  # one command per step
        assert result.missed_commands == 0 and result.rejected_commands == 0, result
        assert f"episode {result.episode} at step {held} held" in sim.log()
    finally:
        procs.stop_all()


def _manager(procs: ProcessSet, *args: str):
    return procs.start(
        "pd_lifecycle_manager", [executable("pd_bringup", "pd_lifecycle_manager"), *args]
    )


def test_the_manager_brings_the_stack_up_in_order_and_down_in_reverse(
    tmp_path, make_node, spin_until, service_ready
):
    procs = ProcessSet(tmp_path)
    try:
        procs.node("pd_sim_node", {**SIM, "auto_restart": True})
        procs.node("pd_policy_node", POLICY)
        procs.node("pd_ocp_node", {"autostart": False})
        manager = _manager(procs)
        assert manager.wait_log("; watching", START_S), procs.logs()
        probe = Probe(
            make_node, spin_until, service_ready, ["pd_ocp_node", "pd_policy_node", "pd_sim_node"]
        )
        assert all(lc.state() == "active" for lc in probe.lc.values())
        assert spin_until(lambda: probe.results, 60.0)  # the stack flies
        up = [ln.split(": ")[1:3] for ln in manager.log().splitlines() if " -> " in ln]
        assert up == [
            ["pd_ocp_node", "configure"],
            ["pd_policy_node", "configure"],
            ["pd_sim_node", "configure"],
            ["pd_ocp_node", "activate"],
            ["pd_policy_node", "activate"],
            ["pd_sim_node", "activate"],
        ]
        assert manager.stop(timeout_s=60.0) == 0, manager.log()
        down = [ln.split(": ")[1:3] for ln in manager.log().splitlines() if " -> " in ln][6:]
        reverse = ["pd_sim_node", "pd_policy_node", "pd_ocp_node"]
        assert down == [[n, t] for t in ("deactivate", "cleanup", "shutdown") for n in reverse]
        assert all(lc.state() == "finalized" for lc in probe.lc.values())
    finally:
        procs.stop_all()


def test_the_manager_takes_the_stack_down_when_a_node_is_killed(
    tmp_path, make_node, spin_until, service_ready
):
    procs = ProcessSet(tmp_path)
    try:
        sim = procs.node("pd_sim_node", {**SIM, "auto_restart": True})
        procs.node("pd_policy_node", POLICY)
        procs.node("pd_ocp_node", {"autostart": False})
        manager = _manager(procs, "--heartbeat-timeout", "4")
        assert manager.wait_log("; watching", START_S), procs.logs()
        probe = Probe(make_node, spin_until, service_ready, ["pd_ocp_node", "pd_policy_node"])
        sim.signal_group(signal.SIGKILL)
        line = "pd_sim_node failed ("
        assert manager.wait_log(line, 30.0), manager.log()
        failed = next(ln for ln in manager.log().splitlines() if line in ln)
        assert failed.endswith("; deactivated pd_policy_node, pd_ocp_node"), failed
        assert probe.lc["pd_policy_node"].state() == "inactive"
        assert probe.lc["pd_ocp_node"].state() == "inactive"
        assert manager.stop(timeout_s=60.0) == 1, manager.log()  # a node failed
        assert "not answering, left as they are: pd_sim_node" in manager.log()
        assert probe.lc["pd_policy_node"].state() == "finalized"
    finally:
        procs.stop_all()


def test_the_old_episode_autostart_false_is_a_deprecated_alias(
    tmp_path, make_node, spin_until, service_ready
):
    procs = ProcessSet(tmp_path)
    try:
        sim = procs.node("pd_sim_node", {"lockstep": True, "autostart": False})
        assert sim.wait_log("simulator ready", START_S), sim.log()
        assert "deprecated" in sim.log() and "start_episode:=false" in sim.log()
        probe = Probe(make_node, spin_until, service_ready, ["pd_sim_node"])
        assert probe.lc["pd_sim_node"].state() == "active"  # started active, no episode
        assert probe.quiet(lambda: len(probe.states))
        reset_cli = probe.node.create_client(ResetEpisode, "/sim/reset")
        assert service_ready(reset_cli)
        answer = probe.lc["pd_sim_node"].call(reset_cli, reset_request(None, 1))
        assert answer.success, answer.message
        assert spin_until(lambda: probe.states, 10.0)
    finally:
        procs.stop_all()


def test_help_lists_the_lifecycle_parameters_and_the_managers_options():
    for package, words in [
        ("pd_sim_node", ["autostart (bool, default True)", "start_episode (bool, default True)"]),
        ("pd_policy_node", ["autostart (bool, default True)"]),
        ("pd_ocp_node", ["autostart (bool, default True)"]),
    ]:
        out = subprocess.run(
            [executable(package, package), "--help"], capture_output=True, text=True, timeout=60
        )
        assert out.returncode == 0 and all(w in out.stdout for w in words), out.stdout
    out = subprocess.run(
        [executable("pd_bringup", "pd_lifecycle_manager"), "--help"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 0, out.stderr
    assert "--nodes" in out.stdout and "--heartbeat-timeout" in out.stdout


def test_the_state_ids_are_lifecycle_msgs_ones():
    assert (lc.UNCONFIGURED, lc.INACTIVE, lc.ACTIVE, lc.FINALIZED) == (
        State.PRIMARY_STATE_UNCONFIGURED,
        State.PRIMARY_STATE_INACTIVE,
        State.PRIMARY_STATE_ACTIVE,
        State.PRIMARY_STATE_FINALIZED,
    )
    assert (lc.CONFIGURE, lc.ACTIVATE, lc.DEACTIVATE, lc.CLEANUP, lc.ACTIVE_SHUTDOWN) == (
        T.TRANSITION_CONFIGURE,
        T.TRANSITION_ACTIVATE,
        T.TRANSITION_DEACTIVATE,
        T.TRANSITION_CLEANUP,
        T.TRANSITION_ACTIVE_SHUTDOWN,
    )
