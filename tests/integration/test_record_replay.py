"""pd_record and pd_replay as real processes, as a ROS 2 user runs them (issue 33 items 1, 2, 5):

- Ctrl-C (SIGINT), SIGTERM, and `ros2 launch`'s SIGINT then SIGTERM stop the recorder mid-flight
  with exit status 0, a metadata.yaml and a bag rosbags reads, also for the topics never heard
  (they crashed the stop: InvalidHandle on the destroyed node), and during type discovery;
- `pd_record -o BAG --ros-args -r __ns:=/vehicle1` records /vehicle1/lander/* and nothing of the
  root namespace (it died in rcl on a bare `-r`);
- /lander/guidance_status (pd_interfaces/msg/GuidanceStatus) is recorded by default and replayed
  field for field;
- on a latest-value topic (lander/path, depth 1) a path replaced before delivery is counted as
  superseded, not lost: exit status 0, and every message sent is either recorded or superseded;
- pd_replay waits for a subscriber by default (a subscriber that comes late gets every message),
  gives up in one line when nobody subscribes, and `--no-wait` publishes at once.
"""

from __future__ import annotations

import itertools
import re
import signal

import pytest
from geometry_msgs.msg import PoseStamped
from helpers import ProcessSet, executable, wait_for
from nav_msgs.msg import Path as PathMsg
from rclpy.serialization import serialize_message
from rosbags.interfaces import QosDurability
from rosbags.rosbag2 import Reader

from pd_bringup import demo
from pd_bringup.bag import bag_qos, deserialize_all, open_writer, read_bag, typestore
from pd_interfaces.msg import GuidanceStatus, LanderState
from pd_ros_common import names, qos
from pd_ros_common.cli import UsageError, split_ros_args

pytestmark = [pytest.mark.integration, pytest.mark.timeout(240)]

START_S = 90.0  # process start-up deadline on a loaded 2-core machine
STOP_S = 30.0  # the recorder stops within a second; generous for a busy machine
ROOT_TOPICS = {names.resolve(t) for t in names.RECORD_TOPICS}  # pd_record's default


def _recorder(procs: ProcessSet, bag, *args: str, name: str = "pd_record"):
    return procs.start(name, [executable("pd_bringup", "pd_record"), "-o", str(bag), *args])


def _stream_states(node, topic: str, episode: int) -> list[int]:
    """Publish LanderState (episode, step 0, 1, ...) on `topic` every 50 ms while the test spins
    its executor ("a flight"); returns the list of steps sent so far."""
    pub = node.create_publisher(LanderState, topic, qos.LOOP_PUB_QOS)
    sent: list[int] = []
    steps = itertools.count()

    def tick() -> None:
        sent.append(next(steps))
        pub.publish(LanderState(episode=episode, step=sent[-1], status=LanderState.FLYING))

    node.create_timer(0.05, tick)
    return sent


def _stop(rec, spin_until, signals: tuple[str, ...]) -> int:
    """Send `signals` to the recorder 0.1 s apart (the flight goes on), wait for its exit."""
    for sig in signals:
        rec.signal_group(getattr(signal, sig))
        spin_until(lambda: False, 0.1)
    assert spin_until(lambda: not rec.alive, STOP_S), f"recorder still running:\n{rec.log()}"
    return rec.proc.returncode


def _summary_count(log: str, topic: str) -> int:
    """Messages of `topic` in the recorder's 'closed BAG (topic: N, ...)' line."""
    found = re.search(rf"closed .*\(.*{re.escape(topic)}: (\d+)", log)
    assert found, log
    return int(found.group(1))


@pytest.mark.parametrize(
    "signals", [("SIGINT",), ("SIGINT", "SIGTERM"), ("SIGTERM",)], ids=lambda s: "-".join(s)
)
def test_recorder_stops_cleanly_mid_flight(tmp_path, make_node, spin_until, signals):
    """Only /lander/state is published: thrust_cmd, episode and guidance_status are never heard."""
    bag = tmp_path / "bag"
    procs = ProcessSet(tmp_path)
    try:
        rec = _recorder(procs, bag)
        sent = _stream_states(make_node("flight_probe"), "/lander/state", episode=1)
        assert spin_until(lambda: "first message on /lander/state" in rec.log(), START_S), rec.log()
        spin_until(lambda: False, 0.5)  # mid-flight
        status = _stop(rec, spin_until, signals)
        log = rec.log()
        assert status == 0, log
    finally:
        procs.stop_all()
    assert "Traceback" not in log and "InvalidHandle" not in log, log
    assert (bag / "metadata.yaml").is_file(), log
    with Reader(bag) as reader:  # the rosbags library, with the metadata
        conns = {c.topic: c for c in reader.connections}
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert set(conns) == ROOT_TOPICS
    assert counts["/lander/thrust_cmd"] == counts["/lander/episode"] == 0, counts
    assert counts["/lander/guidance_status"] == 0, counts
    # a topic never heard keeps the stack's QoS for it: /lander/episode is TRANSIENT_LOCAL
    episode_qos = conns["/lander/episode"].ext.offered_qos_profiles
    assert [q.durability for q in episode_qos] == [QosDurability.TRANSIENT_LOCAL]
    steps = [m.step for m in deserialize_all(bag)["/lander/state"]]
    assert len(steps) >= 3 and len(steps) == counts["/lander/state"]
    # every message from the first one heard on: no gap, nothing left unwritten
    assert steps == list(range(steps[0], steps[0] + len(steps))), steps
    assert steps[-1] <= sent[-1]
    assert _summary_count(log, "/lander/state") == len(steps)


def test_recorder_stopped_while_waiting_for_a_type(tmp_path):
    """A topic of unknown type with no publisher: a Ctrl-C during that wait closes a bag of the
    known topics (it used to wait out --discovery-timeout, then exit with an error)."""
    bag = tmp_path / "bag"
    procs = ProcessSet(tmp_path)
    try:
        args = ("/lander/state", "/nobody/publishes", "--discovery-timeout", "600")
        rec = _recorder(procs, bag, *args)
        assert rec.wait_log("waiting up to 600 s for the type of /nobody/publishes", START_S), (
            rec.log()
        )
        assert rec.stop(timeout_s=STOP_S) == 0, rec.log()
    finally:
        procs.stop_all()
    assert "not recorded" in rec.log() and "Traceback" not in rec.log(), rec.log()
    with Reader(bag) as reader:
        assert [c.topic for c in reader.connections] == ["/lander/state"]


def test_namespaced_form_records_the_namespaced_topics(tmp_path, make_node, spin_until):
    bag = tmp_path / "bag"
    procs = ProcessSet(tmp_path)
    try:
        rec = _recorder(procs, bag, "--ros-args", "-r", "__ns:=/vehicle1")
        node = make_node("two_landers")
        _stream_states(node, "/vehicle1/lander/state", episode=1)
        _stream_states(node, "/lander/state", episode=99)  # another stack, root namespace
        heard = "first message on /vehicle1/lander/state"
        assert spin_until(lambda: heard in rec.log(), START_S), rec.log()
        spin_until(lambda: False, 0.5)
        status = _stop(rec, spin_until, ("SIGINT",))
        assert status == 0, rec.log()
    finally:
        procs.stop_all()
    with Reader(bag) as reader:
        topics = {c.topic for c in reader.connections}
    assert topics == {names.resolve(t, "/vehicle1") for t in names.RECORD_TOPICS}
    states = deserialize_all(bag)["/vehicle1/lander/state"]
    assert len(states) >= 3 and {m.episode for m in states} == {1}


def _guidance(step: int) -> GuidanceStatus:
    """A GuidanceStatus whose every field depends on `step` (so a replay is checked in full)."""
    msg = GuidanceStatus(
        episode=7,
        step=step,
        action=step % 147,
        proposed_action=(step * 5) % 147,
        source=step % 4,
        delay_steps=step % 3,
        thrust_gain_bound=1.0 - step / 1000.0,
        nav_filter_engaged=step % 2 == 1,
        decision_time_s=0.001 * (step + 1),
    )
    msg.header.frame_id = "landing_site"
    msg.header.stamp.sec, msg.header.stamp.nanosec = step // 5, (step % 5) * 200_000_000
    return msg


def _fields(msg) -> tuple:
    """The fields of an rclpy or a rosbags GuidanceStatus."""
    h = msg.header
    return (h.frame_id, h.stamp.sec, h.stamp.nanosec, msg.episode, msg.step, msg.action,
            msg.proposed_action, msg.source, msg.delay_steps, msg.thrust_gain_bound,
            bool(msg.nav_filter_engaged), msg.decision_time_s)  # fmt: skip


def test_guidance_status_recorded_by_default_and_replayed(tmp_path, make_node, spin_until):
    bag = tmp_path / "bag"
    procs = ProcessSet(tmp_path)
    try:
        rec = _recorder(procs, bag)  # no topic named: the stack's default topics
        node = make_node("policy_stand_in")
        pub = node.create_publisher(GuidanceStatus, "/lander/guidance_status", qos.LOOP_PUB_QOS)
        steps = itertools.count()
        timer = node.create_timer(0.05, lambda: pub.publish(_guidance(next(steps))))
        heard = "first message on /lander/guidance_status"
        assert spin_until(lambda: heard in rec.log(), START_S), rec.log()
        spin_until(lambda: False, 0.5)
        timer.cancel()
        spin_until(lambda: False, 0.5)
        assert _stop(rec, spin_until, ("SIGINT",)) == 0, rec.log()
        recorded = deserialize_all(bag)["/lander/guidance_status"]  # rosbags decodes it
        assert len(recorded) >= 3
        assert [_fields(m) for m in recorded] == [_fields(_guidance(m.step)) for m in recorded]

        # The replay starts before anyone subscribes: it waits, and a late subscriber gets all.
        rep = procs.start(
            "pd_replay",
            [executable("pd_bringup", "pd_replay"), str(bag), "--rate", "5",
             "--ros-args", "-r", "__node:=pd_replay_guidance"],
        )  # fmt: skip
        assert rep.wait_log("waiting for 1 subscriber(s) of /lander/guidance_status", START_S), (
            rep.log()
        )
        assert rep.alive and "published" not in rep.log(), rep.log()
        got: list[GuidanceStatus] = []
        node.create_subscription(
            GuidanceStatus, "/lander/guidance_status", got.append, qos.LOOP_SUB_QOS
        )
        assert spin_until(lambda: len(got) >= len(recorded), 60.0), (len(got), rep.log())
        assert wait_for(lambda: not rep.alive, 30.0) and rep.proc.returncode == 0, rep.log()
        # (the bag holds the recorder's own /diagnostics too: replayed, nobody waited for)
        assert f"published {len(read_bag(bag).messages)} messages" in rep.log(), rep.log()
        assert [_fields(m) for m in got] == [_fields(m) for m in recorded]
    finally:
        procs.stop_all()


def _path(k: int, poses: int = 2000) -> PathMsg:
    """The k-th path of a burst (header.stamp.sec = k), `poses` long: big enough that a burst
    overflows a stopped reader's socket buffer, so what the depth-1 writer replaced never
    reaches it."""
    msg = PathMsg(poses=[PoseStamped() for _ in range(poses)])
    msg.header.frame_id, msg.header.stamp.sec = "landing_site", k
    return msg


def test_a_superseded_path_is_counted_not_lost(tmp_path, make_node, spin_until):
    """A burst on lander/path (PATH_QOS, depth 1) while the recorder is stopped (SIGSTOP): what
    the writer replaced before delivery is 'superseded' in the summary, never LOST, and exit
    status is 0; recorded + superseded is exactly what was sent after the recorder's first
    message, and the last path arrives."""
    bag, sent = tmp_path / "bag", 300
    procs = ProcessSet(tmp_path)
    try:
        rec = _recorder(procs, bag, "/lander/path")
        node = make_node("path_burst")
        pub = node.create_publisher(PathMsg, "/lander/path", qos.PATH_QOS)
        assert spin_until(lambda: pub.get_subscription_count() >= 1, START_S), rec.log()
        pub.publish(_path(0))
        assert spin_until(lambda: "first message on /lander/path" in rec.log(), START_S)
        burst = [_path(k) for k in range(1, sent - 1)]
        rec.signal_group(signal.SIGSTOP)  # a recorder that cannot keep up: nothing acknowledged
        try:
            for msg in burst:
                pub.publish(msg)
            spin_until(lambda: False, 0.5)
        finally:
            rec.signal_group(signal.SIGCONT)
        spin_until(lambda: False, 0.5)
        pub.publish(_path(sent - 1))  # sent to a reader that keeps up: it arrives at once
        spin_until(lambda: False, 2.0)
        assert _stop(rec, spin_until, ("SIGINT",)) == 0, rec.log()
    finally:
        procs.stop_all()
    log = rec.log()
    assert "LOST" not in log and "never reached" not in log, log
    recorded = _summary_count(log, "/lander/path")
    found = re.search(r"/lander/path: \d+, (\d+) superseded", log)
    superseded = int(found.group(1)) if found else 0
    assert recorded + superseded == sent and superseded > 0, log
    paths = deserialize_all(bag)["/lander/path"]
    assert len(paths) == recorded and paths[-1].header.stamp.sec == sent - 1
    print(f"{recorded} recorded, {superseded} superseded of {sent}")


def _small_bag(path, n: int = 3):
    """A bag of n GuidanceStatus written here (no recorder), offered QoS the stack's."""
    writer = open_writer(path)
    conn = writer.add_connection(
        "/lander/guidance_status",
        "pd_interfaces/msg/GuidanceStatus",
        typestore=typestore(),
        offered_qos_profiles=[bag_qos(qos.LOOP_PUB_QOS)],
    )
    for k in range(n):
        writer.write(conn, 1_000_000_000 + k * 10_000_000, serialize_message(_guidance(k)))
    writer.close()
    return path


@pytest.mark.parametrize(
    ("flags", "status", "says"),
    [
        (["--wait-timeout", "3"], 1, "no subscriber to any replayed topic after 3 s"),
        (["--no-wait"], 0, "published 3 messages"),
    ],
)
def test_replay_without_subscribers(tmp_path, flags, status, says):
    bag = _small_bag(tmp_path / "bag")
    procs = ProcessSet(tmp_path)
    try:
        rep = procs.start("pd_replay", [executable("pd_bringup", "pd_replay"), str(bag), *flags])
        assert wait_for(lambda: not rep.alive, START_S), rep.log()
    finally:
        procs.stop_all()
    assert rep.proc.returncode == status and says in rep.log(), rep.log()
    if status:
        assert "messages from" not in rep.log(), rep.log()


def test_tools_take_ros_args_anywhere():
    """argparse never sees a --ros-args section; a bare FROM:=TO outside one is the tool's own
    (pd_replay --remap) and never reaches rcl; a malformed section is a UsageError."""
    args = demo.parse_args(["--fast", "--ros-args", "-r", "__ns:=/v1", "--", "--seed", "3"])
    assert args.fast and args.seed == 3
    argv = ["bag", "--remap", "/a:=/b", "--ros-args", "-r", "__node:=x", "--", "--rate", "2",
            "--ros-args", "-p", "use_sim_time:=true"]  # fmt: skip
    own, ros = split_ros_args("pd_replay", argv)
    assert own == ["bag", "--remap", "/a:=/b", "--rate", "2"]
    assert ros == ["--ros-args", "-r", "__node:=x", "-p", "use_sim_time:=true"]
    assert split_ros_args("pd_record", ["-o", "b"]) == (["-o", "b"], [])
    for bad, says in ((["--ros-args", "-r"], "trailing -r"), (["--ros-args", "x"], "unknown")):
        with pytest.raises(UsageError, match=says):
            split_ros_args("pd_record", bad)


def test_a_restarted_simulator_is_recorded_or_counted_to_the_message(
    tmp_path, make_node, spin_until
):
    """Issue 71 item 6: a simulator SIGKILLed mid-episode and started again while pd_record
    records. A new publisher's first messages go out before DDS matches it with the recorder
    (reliable, volatile: never sent to a later reader); the recorder counts them from the
    sequence numbers. Every state of each simulator from step 0 is in the bag or counted."""
    procs = ProcessSet(tmp_path)
    bag = tmp_path / "bag"
    sim = {"rate_hz": 20.0, "start_wait_s": 0.0, "auto_restart": True, "seed": 5}
    heard: list[LanderState] = []
    probe = make_node("restart_probe")
    probe.create_subscription(LanderState, "/lander/state", heard.append, qos.LOOP_SUB_QOS)
    try:
        rec = _recorder(procs, bag, "/lander/state")
        assert rec.wait_log("publishers that appear from now on are new", START_S), rec.log()
        first = procs.node("pd_sim_node", {**sim, "lander_id": "first"})
        assert spin_until(lambda: sum(s.lander_id == "first" for s in heard) >= 20, START_S)
        # the assertions need the recorder matched with the first simulator before it dies (a
        # publisher killed before it matched is never seen, so nothing of it can be counted)
        assert spin_until(lambda: "first message on /lander/state" in rec.log(), START_S)
        first.signal_group(signal.SIGKILL)  # mid-episode (a zero-thrust fall lasts ~25 s)
        assert wait_for(lambda: not first.alive, 10.0)
        second = procs.node("pd_sim_node", {**sim, "lander_id": "second"}, name="pd_sim_2")
        assert spin_until(lambda: sum(s.lander_id == "second" for s in heard) >= 40, START_S)
        assert rec.stop(timeout_s=STOP_S) == 0, rec.log()
        second.stop()
    finally:
        procs.stop_all()

    recorded = deserialize_all(bag)["/lander/state"]
    skipped = 0
    for lander in ("first", "second"):
        steps = [(m.episode, m.step) for m in recorded if m.lander_id == lander]
        assert steps and steps[0][0] == 1, (lander, steps[:3])
        start = steps[0][1]  # states of episode 1 before this one never reached the recorder
        assert steps == [(1, k) for k in range(start, start + len(steps))], lander  # no gap
        skipped += start
    missed = re.search(r"/lander/state: \d+(?:, [^,]*)*?, (\d+) missed before", rec.log())
    said = int(missed.group(1)) if missed else 0
    assert said == skipped, (said, skipped, rec.log()[-1500:])
    meta = (bag / "metadata.yaml").read_text()
    custom = f"/lander/state {skipped}" if skipped else "'0'"
    assert f"pd_record.missed_before_match: {custom}" in meta, meta
