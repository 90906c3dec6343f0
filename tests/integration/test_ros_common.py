"""pd_ros_common: parameter coercion and checks, sequence gaps, publisher names, sessions,
names, domains, the readers a writer reports on /diagnostics; the simulator's command_source
check."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest
import rclpy
from rcl_interfaces.srv import GetParameters
from std_msgs.msg import String

from pd_ros_common import diagnostics, names, params
from pd_ros_common.domain import claim_domain_id
from pd_ros_common.gaps import SequenceGaps
from pd_ros_common.session import RosSession, wait_for_server
from pd_ros_common.sources import PublisherNames
from pd_sim_node.node import CHECKS as SIM_CHECKS
from pd_sim_node.node import PARAMETERS as SIM_PARAMS

pytestmark = [pytest.mark.integration]

SPEC = {
    "rate_hz": (5.0, "a double"),
    "seed": (0, "an integer"),
    "lockstep": (False, "a bool"),
    "mode": ("hold", "a string"),
    "state": ([0.0], "doubles"),
}
CHECKS = {"rate_hz": params.above(0.0), "mode": params.one_of(("hold", "zero"))}


@pytest.mark.parametrize(
    ("name", "value", "want"),
    [
        ("rate_hz", 10, 10.0),
        ("rate_hz", 2.5, 2.5),
        ("seed", 7, 7),
        ("lockstep", True, True),
        ("mode", "zero", "zero"),
        ("state", [0, 1, 2.5], [0.0, 1.0, 2.5]),
    ],
)
def test_values_coerced(name, value, want):
    got = params.check_value(name, value, SPEC, CHECKS)
    assert got == want and type(got) is type(want)


@pytest.mark.parametrize(
    ("name", "value", "says"),
    [
        ("rate_hz", "abc", "parameter rate_hz: expected a double"),
        ("rate_hz", True, "expected a double"),
        ("rate_hz", 0, "parameter rate_hz: must be > 0 (got 0.0)"),
        ("rate_hz", float("nan"), "must be > 0"),
        ("seed", 1.5, "parameter seed: expected an integer"),
        ("lockstep", 1, "expected a bool"),
        ("mode", "bogus", "parameter mode: must be one of hold, zero (got 'bogus')"),
        ("state", ["x"], "expected a list of doubles"),
    ],
)
def test_bad_values_refused_in_one_line(name, value, says):
    with pytest.raises(params.ParameterError) as err:
        params.check_value(name, value, SPEC, CHECKS)
    assert says.replace("a integer", "an integer") in str(err.value).replace(
        "a integer", "an integer"
    )
    assert "\n" not in str(err.value)


def _info(gid: bytes, seq: int) -> dict:
    return {"publisher_gid": {"data": gid}, "publication_sequence_number": seq}


def test_sequence_gaps_per_publisher():
    gaps = SequenceGaps()
    assert gaps.update(_info(b"a", 5)) == (0, 0, 0)  # first seen: earlier ones are not lost
    assert gaps.update(_info(b"b", 1)) == (0, 0, 0)
    assert gaps.update(_info(b"a", 6)) == (0, 0, 0)
    assert gaps.update(_info(b"a", 10)) == (3, 7, 9)
    assert gaps.update(_info(b"b", 2)) == (0, 0, 0)
    assert gaps.update(_info(b"a", 9)) == (0, 0, 0)  # late, not a new gap
    assert gaps.update({"publication_sequence_number": None}) == (0, 0, 0)
    assert gaps.total == 3


class _Endpoint:
    def __init__(self, name: str, gid: bytes) -> None:
        self.node_name, self.endpoint_gid = name, list(gid)


def test_publisher_names_resolve_from_the_graph_and_are_cached():
    graph = [_Endpoint("pd_policy_node", b"p" * 16)]
    names_ = PublisherNames(lambda: graph)
    assert names_.name_of(_info(b"p" * 16, 1)) == "pd_policy_node"
    assert names_.name_of(_info(b"p" * 16, 2)) == "pd_policy_node" and names_.lookups == 1
    assert names_.name_of(_info(b"s" * 16, 1)) == ""  # not discovered yet: asked again next time
    graph.append(_Endpoint("_NODE_NAME_UNKNOWN_", b"s" * 16))  # writer seen, node not yet
    assert names_.name_of(_info(b"s" * 16, 2)) == ""
    graph[-1] = _Endpoint("stray", b"s" * 16)
    assert names_.name_of(_info(b"s" * 16, 3)) == "stray" and names_.lookups == 4
    assert names_.name_of({"publication_sequence_number": 1}) == ""


@pytest.mark.parametrize(
    ("value", "ok"), [("", True), ("pd_policy_node", True), ("my_ctl2", True), ("/ns/x", False)]
)
def test_sim_command_source_must_be_a_node_name(value, ok):
    if ok:
        assert params.check_value("command_source", value, SIM_PARAMS, SIM_CHECKS) == value
    else:
        with pytest.raises(params.ParameterError, match="must be a node name"):
            params.check_value("command_source", value, SIM_PARAMS, SIM_CHECKS)


def test_names_are_relative_and_resolve():
    assert all(not n.startswith("/") for n in (*names.LANDER_TOPICS, names.RESET_SERVICE))
    assert names.resolve(names.STATE_TOPIC) == "/lander/state"
    assert names.resolve(names.OCP_SERVICE, "/vehicle1") == "/vehicle1/ocp/compute_trajectory"


def test_domain_claims_differ_and_override(monkeypatch):
    a, fd_a = claim_domain_id()
    b, fd_b = claim_domain_id()
    try:
        assert a != b and 1 <= a <= 101 and 1 <= b <= 101
        monkeypatch.setenv("PD_FORCED_DOMAIN", "42")
        assert claim_domain_id("PD_FORCED_DOMAIN") == (42, None)
    finally:
        os.close(fd_a)
        os.close(fd_b)


def test_a_hanging_teardown_exits_with_the_status_and_one_line():
    """The watchdog run_node arms before the shutdown transition: a stuck teardown exits."""
    code = (
        "import time\n"
        "from pd_ros_common import run\n"
        "run.TEARDOWN_S = 0.2\n"
        "run._exit_if_teardown_hangs('pd_x_node', 2)\n"
        "time.sleep(30)\n"
    )
    t0 = time.monotonic()
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=20)
    assert out.returncode == 2 and time.monotonic() - t0 < 15.0
    assert out.stderr.strip() == "pd_x_node: DDS teardown took over 0.2 s; exiting anyway"
    # a teardown that finishes cancels it
    code = code.replace("run._exit", "w = run._exit").replace("time.sleep(30)", "w.cancel()")
    out = subprocess.run([sys.executable, "-c", code + "time.sleep(0.5)\n"], timeout=20)
    assert out.returncode == 0


def test_a_teardown_that_holds_the_gil_still_exits_and_says_where():
    """A C call that never releases the GIL stops the Python timer; faulthandler's C thread
    dumps the stacks and exits (status 1) after 1.5 TEARDOWN_S."""
    code = (
        "import ctypes\n"
        "from pd_ros_common import run\n"
        "run.TEARDOWN_S = 0.2\n"
        "run._exit_if_teardown_hangs('pd_x_node', 0)\n"
        "ctypes.PyDLL(None).sleep(30)\n"  # PyDLL keeps the GIL through the call
    )
    t0 = time.monotonic()
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=20)
    assert out.returncode == 1 and time.monotonic() - t0 < 15.0
    assert "Timeout" in out.stderr and "<string>" in out.stderr, out.stderr


def test_two_sessions_hear_each_other_and_close_only_their_own_context():
    """Tools and benches each own a session: one hears the other's message, and closing both
    leaves rclpy's global context (a caller's) as it was."""
    was_ok = rclpy.ok()
    with RosSession("pd_test_talker") as talker, RosSession("pd_test_listener") as listener:
        heard: list[str] = []
        listener.node.create_subscription(
            String, "session_probe", lambda m: heard.append(m.data), 10
        )
        pub = talker.node.create_publisher(String, "session_probe", 10)
        assert listener.spin_until(lambda: pub.get_subscription_count() == 1, 10.0)
        msg = String(data="hello")

        def publish_and_check() -> None:
            pub.publish(msg)
            talker.spin_once(0.0)

        assert listener.spin_until(lambda: heard, 10.0, check=publish_and_check)
        assert heard[0] == "hello"
    assert not talker.context.ok() and not listener.context.ok()
    assert rclpy.ok() == was_ok


def test_wait_for_server_is_false_without_one_and_a_first_request_is_answered():
    """`session.wait_for_server` says False when nobody serves; once it says True, the first
    request of a fresh client is answered (the server has discovered the client as well)."""
    with RosSession("pd_test_client") as me:
        cli = me.node.create_client(GetParameters, "/pd_test_server/get_parameters")
        t0 = time.monotonic()
        assert not wait_for_server(me.executor, cli, 0.3)
        assert time.monotonic() - t0 < 2.0
        with RosSession("pd_test_server") as server:
            assert wait_for_server(me.executor, cli, 10.0)
            future = cli.call_async(GetParameters.Request(names=["use_sim_time"]))
            assert me.spin_until(future.done, 10.0, check=lambda: server.spin_once(0.0))
            assert future.result().values[0].bool_value is False


def test_a_writer_reports_each_reader_it_has_matched_on_diagnostics():
    """`diagnostics.readers` counts DDS-matched subscriptions: 0, then 2 once two sessions
    subscribe; `diagnostics.Listener.readers` reads the latest figure (-1 before any)."""
    with RosSession("pd_test_writer") as writer, RosSession("pd_test_watch") as watch:
        pub = writer.node.create_publisher(String, "readers_probe", 10)

        def report() -> diagnostics.Report:
            return diagnostics.Report(values=diagnostics.readers(pub))

        diagnostics.Diagnostics(writer.node, "probe", report, period_s=0.1)
        listener = diagnostics.Listener(watch.node)
        topic = "/readers_probe"
        assert listener.readers(topic) == -1

        def heard(n: int) -> bool:
            return listener.readers(topic) == n

        assert watch.spin_until(lambda: heard(0), 10.0, check=lambda: writer.spin_once(0.0))
        assert listener.values("pd_test_writer: probe") == {f"readers {topic}": "0"}
        watch.node.create_subscription(String, "readers_probe", lambda m: None, 10)
        with RosSession("pd_test_reader") as reader:
            reader.node.create_subscription(String, "readers_probe", lambda m: None, 10)
            assert watch.spin_until(lambda: heard(2), 10.0, check=lambda: writer.spin_once(0.0))
