"""pd_sim_node in lockstep with pd_policy_node, as real processes over DDS.

One simulator and one policy node serve the whole module (start-up with torch costs seconds):
- a lockstep landing over ROS ends in exactly the states of the offline pd_core rollout;
- a NaN state, an out-of-range action, a NaN thrust and a stale command are each rejected, and
  the loop goes on (also across a policy-node restart), still bit-identical to the offline run;
- pd_record records state and commands, the bag reads back with rosbags, and replaying the states
  into a fresh policy node reproduces the recorded commands exactly.
"""

from __future__ import annotations

import math
import signal

import numpy as np
import pytest
from geometry_msgs.msg import Vector3
from helpers import ProcessSet, executable, make_model, offline_rollout, table3_state, wait_for
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from pd_core.actions import DEFAULT_ACTIONS
from pd_interfaces.msg import EpisodeResult, LanderState, ThrustCommand
from pd_interfaces.srv import ResetEpisode

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.timeout(300)]

QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1000,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
START_S = 90.0  # deadline for a node process to come up (2 cores shared with other work)


@pytest.fixture(scope="module")
def stack(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("lockstep")
    model = make_model(tmp / "untrained.pt", seed=1)
    procs = ProcessSet(tmp)
    try:
        sim = procs.node("pd_sim_node", {"lockstep": True, "start_episode": False})
        policy = procs.node("pd_policy_node", {"model_path": str(model)})
        assert sim.wait_log("simulator ready", START_S), procs.logs()
        assert policy.wait_log("policy ready", START_S), procs.logs()
        yield {"procs": procs, "sim": sim, "policy": policy, "model": model, "tmp": tmp}
    finally:
        procs.stop_all()


class Loop:
    """The test's view of the loop: collects states, commands and results; resets episodes."""

    def __init__(self, make_node, spin_until, name: str = "lockstep_probe"):
        self.node = make_node(name)
        self.spin_until = spin_until
        self.states: list[LanderState] = []
        self.commands: list[ThrustCommand] = []
        self.results: list[EpisodeResult] = []
        self.node.create_subscription(LanderState, "/lander/state", self.states.append, QOS)
        self.node.create_subscription(
            ThrustCommand, "/lander/thrust_cmd", self.commands.append, QOS
        )
        self.node.create_subscription(EpisodeResult, "/lander/episode", self.results.append, QOS)
        self.reset_client = self.node.create_client(ResetEpisode, "/sim/reset")
        self.cmd_pub = self.node.create_publisher(ThrustCommand, "/lander/thrust_cmd", QOS)
        self.state_pub = self.node.create_publisher(LanderState, "/lander/state", QOS)
        assert spin_until(self.reset_client.service_is_ready, 20.0), "no /sim/reset"
        # Our subscriptions and publishers matched with the nodes' before anything flies.
        assert spin_until(
            lambda: (
                self.node.count_publishers("/lander/state") >= 2
                and self.node.count_publishers("/lander/thrust_cmd") >= 2
                and self.cmd_pub.get_subscription_count() >= 1
            ),
            20.0,
        )
        self.spin_until(lambda: False, 0.5)  # let discovery settle both ways

    def reset(self, state: np.ndarray, seed: int) -> int:
        req = ResetEpisode.Request(use_initial_state=True, mass=float(state[6]), seed=seed)
        req.position = Vector3(x=state[0], y=state[1], z=state[2])
        req.velocity = Vector3(x=state[3], y=state[4], z=state[5])
        future = self.reset_client.call_async(req)
        assert self.spin_until(future.done, 10.0), "reset timed out"
        resp = future.result()
        assert resp.success, resp.message
        return resp.episode

    def result_of(self, episode: int, timeout_s: float) -> EpisodeResult:
        def found():
            return any(r.episode == episode for r in self.results)

        assert self.spin_until(found, timeout_s), f"episode {episode} did not end in time"
        result = next(r for r in self.results if r.episode == episode)
        # The result may overtake states still queued in our subscription: drain them.
        self.spin_until(lambda: len(self.states_of(episode)) > result.steps, 10.0)
        return result

    def states_of(self, episode: int) -> list[LanderState]:
        seen: dict[int, LanderState] = {}
        for s in self.states:
            if s.episode == episode:
                seen.setdefault(s.step, s)
        return [seen[k] for k in sorted(seen)]


def vec(msg: LanderState) -> np.ndarray:
    p, v = msg.position, msg.velocity
    return np.array([p.x, p.y, p.z, v.x, v.y, v.z, msg.mass])


def command(episode: int, step: int, action: int, thrust=None) -> ThrustCommand:
    t = DEFAULT_ACTIONS.table_n[action % DEFAULT_ACTIONS.n] if thrust is None else thrust
    msg = ThrustCommand(episode=episode, step=step, action=action)
    msg.thrust = Vector3(x=float(t[0]), y=float(t[1]), z=float(t[2]))
    return msg


def assert_matches_offline(loop: Loop, episode: int, expected: list[np.ndarray]) -> None:
    result = loop.result_of(episode, 60.0)
    got = loop.states_of(episode)
    assert result.steps == len(expected) - 1
    assert len(got) == len(expected), "states were lost"
    for msg, want in zip(got, expected, strict=True):
        np.testing.assert_array_equal(vec(msg), want)  # exactly, not approximately
    final = np.array(
        [
            result.final_position.x,
            result.final_position.y,
            result.final_position.z,
            result.final_velocity.x,
            result.final_velocity.y,
            result.final_velocity.z,
            result.final_mass,
        ]
    )
    np.testing.assert_array_equal(final, expected[-1])
    assert result.missed_commands == 0


def test_lockstep_landing_equals_offline_rollout(stack, make_node, spin_until):
    loop = Loop(make_node, spin_until)
    s0, seed = table3_state(100), 11
    expected = offline_rollout(stack["model"], seed, s0)
    episode = loop.reset(s0, seed)
    assert_matches_offline(loop, episode, expected)
    result = loop.result_of(episode, 1.0)
    assert result.rejected_commands == 0
    assert result.status != LanderState.FLYING
    assert math.isclose(result.time_of_flight, 0.2 * result.steps)

    # Commands come from another writer than the result: the last may still be on its way.
    def cmds():
        return [c for c in loop.commands if c.episode == episode]

    def every_step_commanded() -> bool:
        return sorted(c.step for c in cmds()) == list(range(result.steps))

    spin_until(every_step_commanded, 5.0)
    assert every_step_commanded(), sorted(c.step for c in cmds())


def test_bad_inputs_rejected_and_loop_goes_on(stack, make_node, spin_until):
    """NaN state (policy), unknown action, NaN thrust, mismatched thrust, stale command (sim)."""
    loop = Loop(make_node, spin_until)
    policy = stack["policy"]

    # 1. A state with NaN values: logged by the policy node, answered with no command.
    bad = LanderState(episode=4242, step=7, mass=1900.0, status=LanderState.FLYING)
    bad.position = Vector3(x=math.nan, y=0.0, z=100.0)
    loop.state_pub.publish(bad)
    assert policy.wait_log("episode 4242 step 7 rejected", 10.0), policy.log()
    spin_until(lambda: False, 0.5)
    assert not any(c.episode == 4242 for c in loop.commands)

    # 2. Freeze the loop mid-flight by stopping the policy; the simulator waits (lockstep).
    s0, seed = table3_state(200), 12
    expected = offline_rollout(stack["model"], seed, s0)
    assert policy.stop() == 0, policy.log()
    episode = loop.reset(s0, seed)
    assert spin_until(lambda: len(loop.states_of(episode)) >= 1, 10.0)
    # Fly three steps ourselves with valid commands (the expected actions).
    from pd_core import load_policy

    pol = load_policy(stack["model"])
    for k in range(3):
        loop.cmd_pub.publish(command(episode, k, pol.bare_action(expected[k])))
        assert spin_until(lambda k=k: len(loop.states_of(episode)) >= k + 2, 10.0)
    step = 3
    sim = stack["sim"]
    for msg, reason in [
        (command(episode, step, 500, (0.0, 0.0, 0.0)), "unknown action 500"),
        (command(episode, step, 10, (math.nan, 0.0, 0.0)), "NaN or infinite"),
        (command(episode, step, 10, (1.0, 2.0, 3.0)), "does not match action 10"),
        (command(episode, step - 1, 10), "stale command"),
    ]:
        loop.cmd_pub.publish(msg)
        assert sim.wait_log(reason, 10.0), sim.log()
    spin_until(lambda: False, 0.3)
    assert len(loop.states_of(episode)) == step + 1, "a rejected command was applied"

    # 3. A fresh policy node picks the loop up (the simulator republishes the waiting state).
    stack["policy"] = stack["procs"].node(
        "pd_policy_node", {"model_path": str(stack["model"])}, name="pd_policy_node_2"
    )
    assert_matches_offline(loop, episode, expected)  # rejected commands were never applied
    result = loop.result_of(episode, 1.0)
    assert result.rejected_commands == 4
    assert "[4 rejected so far]" in sim.log()
    assert stack["sim"].alive and stack["policy"].alive


def test_record_then_replay_reproduces_commands(stack, make_node, spin_until):
    from pd_bringup.bag import deserialize_all

    procs: ProcessSet = stack["procs"]
    loop = Loop(make_node, spin_until, "record_probe")
    assert stack["policy"].wait_log("policy ready", START_S)
    assert spin_until(lambda: loop.node.count_subscribers("/lander/state") >= 2, START_S)
    bag = stack["tmp"] / "bag"
    rec = procs.start(
        "pd_record",
        [
            executable("pd_bringup", "pd_record"),
            "-o",
            str(bag),
            "/lander/state",
            "/lander/thrust_cmd",
            "/lander/episode",
        ],
    )
    assert rec.wait_log("recording", START_S), rec.log()
    assert spin_until(lambda: loop.node.count_subscribers("/lander/thrust_cmd") >= 3, 10.0)

    # A warm-up episode proves DDS matching is complete both ways (a writer that has not yet
    # matched the recorder's reader would not send it the first messages of the real episode).
    # A whole lockstep episode can end before matching completes, so fly warm-ups until the
    # recorder has heard both topics.
    def heard() -> bool:
        return all(
            f"first message on {t}" in rec.log() for t in ("/lander/state", "/lander/thrust_cmd")
        )

    warmups = 0
    while warmups < 5 and not heard():
        warmups += 1
        loop.result_of(loop.reset(table3_state(299), 12), 60.0)
        wait_for(heard, 2.0)
    assert heard(), f"recorder heard nothing after {warmups} warm-ups: {rec.log()}"
    episode = loop.reset(table3_state(300), 13)
    result = loop.result_of(episode, 60.0)
    spin_until(lambda: False, 0.5)
    assert rec.stop(sig=signal.SIGTERM, timeout_s=10.0) == 0, rec.log()
    assert "closed" in rec.log()

    recorded = deserialize_all(bag)  # rosbags reads it back (its own CDR decoder)
    states = [m for m in recorded["/lander/state"] if m.episode == episode]
    cmds = [m for m in recorded["/lander/thrust_cmd"] if m.episode == episode]
    assert len(states) == result.steps + 1
    assert len(cmds) == result.steps
    assert [r.episode for r in recorded["/lander/episode"]][-1:] == [episode]
    assert (bag / "metadata.yaml").is_file() and list(bag.glob("*.mcap"))

    # Replay the recorded states into a fresh policy node on other topic names.
    fresh = procs.node(
        "pd_policy_node",
        {"model_path": str(stack["model"])},
        remaps={
            "/lander/state": "/replay/state",
            "/lander/thrust_cmd": "/replay/thrust_cmd",
            "__node": "pd_policy_replay",
        },
        name="pd_policy_replay",
    )
    replayed: list[ThrustCommand] = []
    loop.node.create_subscription(ThrustCommand, "/replay/thrust_cmd", replayed.append, QOS)
    assert fresh.wait_log("policy ready", START_S), fresh.log()
    assert spin_until(lambda: loop.node.count_publishers("/replay/thrust_cmd") >= 1, 10.0)
    spin_until(lambda: False, 0.5)
    rep = procs.start(
        "pd_replay",
        [
            executable("pd_bringup", "pd_replay"),
            str(bag),
            "--topics",
            "/lander/state",
            "--remap",
            "/lander/state:=/replay/state",
            "--rate",
            "0.5",
            "--wait-subscribers",
            "1",
        ],
    )
    n_states = len(recorded["/lander/state"])
    n_flying = sum(1 for m in recorded["/lander/state"] if m.status == LanderState.FLYING)
    from rosbags.rosbag2 import Reader

    with Reader(bag) as reader:  # replay at half speed takes twice the recorded span
        replay_s = 2.0 * reader.duration * 1e-9 + 30.0
    assert spin_until(lambda: len(replayed) >= n_flying, replay_s), (len(replayed), n_flying)
    assert wait_for(lambda: not rep.alive, 20.0)
    assert f"published {n_states} messages" in rep.log()

    def key(c):
        t = c.thrust
        return (
            c.episode,
            c.step,
            c.action,
            t.x,
            t.y,
            t.z,
            c.header.stamp.sec,
            c.header.stamp.nanosec,
        )

    # The episode under test, every command (the warm-up may have started before matching).
    assert [key(c) for c in replayed if c.episode == episode] == [key(c) for c in cmds]
    fresh.stop()


def test_every_process_alive(stack):
    assert stack["sim"].alive, stack["procs"].logs()
    assert stack["policy"].alive, stack["procs"].logs()
