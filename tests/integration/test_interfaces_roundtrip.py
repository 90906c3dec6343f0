"""pd_interfaces round-trips through real DDS: each message over a publisher/subscription pair,
each service through a server and a client, all in this process (see conftest.py)."""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import pytest
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Vector3
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Header

from pd_interfaces.msg import EpisodeResult, LanderState, ThrustCommand
from pd_interfaces.srv import ComputeTrajectory, ResetEpisode

pytestmark = [pytest.mark.integration, pytest.mark.timeout(60)]

QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)


def vec(x: float, y: float, z: float) -> Vector3:
    return Vector3(x=x, y=y, z=z)


def header(sec: int, nanosec: int, frame: str = "landing_site") -> Header:
    return Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id=frame)


def make_lander_state() -> LanderState:
    return LanderState(
        header=header(12, 400_000_000),
        episode=7,
        step=62,
        position=vec(-123.25, 45.5, 1508.125),
        velocity=vec(10.0 / 3.0, -0.1, -75.2),
        mass=1905.75,
        status=LanderState.CRASHED,
    )


def make_thrust_command() -> ThrustCommand:
    return ThrustCommand(
        header=header(3, 123_456_789),
        episode=4_000_000_000,  # near the uint32 limit
        step=17,
        action=146,
        thrust=vec(-1234.5, 0.25, 16573.0),
    )


def make_episode_result() -> EpisodeResult:
    return EpisodeResult(
        header=header(80, 200_000_000),
        episode=9,
        steps=401,
        time_of_flight=80.2,
        initial_position=vec(1500.0, -300.0, 2000.0),
        initial_velocity=vec(-75.0, 20.0, -90.0),
        final_position=vec(1.5, -0.75, 0.005),
        final_velocity=vec(0.1, -0.2, -1.9),
        final_mass=1630.0625,
        fuel=269.9375,
        landed=True,
        status=LanderState.LANDED,
        reason="landed: altitude < 0.01 m, |x| < 5 m, |v| < 2 m/s",
        rejected_commands=2,
        missed_commands=3,
    )


def test_lander_state_constants_are_distinct() -> None:
    constants = [
        LanderState.FLYING,
        LanderState.LANDED,
        LanderState.CRASHED,
        LanderState.OUT_OF_TIME,
    ]
    assert len(set(constants)) == len(constants)


@pytest.mark.parametrize(
    ("msg_type", "make_msg"),
    [
        (LanderState, make_lander_state),
        (ThrustCommand, make_thrust_command),
        (EpisodeResult, make_episode_result),
    ],
    ids=["LanderState", "ThrustCommand", "EpisodeResult"],
)
def test_message_roundtrip(
    msg_type: type, make_msg: Callable[[], object], make_node, spin_until
) -> None:
    topic = f"/pd_test/roundtrip/{msg_type.__name__}"
    received: list = []
    listener = make_node("roundtrip_listener")
    listener.create_subscription(msg_type, topic, received.append, QOS)
    talker = make_node("roundtrip_talker")
    publisher = talker.create_publisher(msg_type, topic, QOS)

    assert spin_until(lambda: publisher.get_subscription_count() >= 1, timeout_sec=10.0), (
        "subscription never matched the publisher"
    )
    sent = make_msg()
    # Re-publish until heard: the writer may see the match a moment before the reader does.
    deadline = time.monotonic() + 10.0
    while not received and time.monotonic() < deadline:
        publisher.publish(sent)
        spin_until(lambda: bool(received), timeout_sec=0.5)
    assert received, f"no {msg_type.__name__} received on {topic}"

    got = received[0]
    assert got is not sent
    assert isinstance(got, msg_type)
    expected = make_msg()  # built afresh: `sent` could not have been altered on the way
    for field in expected.get_fields_and_field_types():
        assert getattr(got, field) == getattr(expected, field), field
    assert got == expected


def expected_reset_response(request: ResetEpisode.Request) -> ResetEpisode.Response:
    return ResetEpisode.Response(
        success=request.use_initial_state,
        message=f"episode started with seed {request.seed}",
        episode=41 + int(request.seed % 7),
        position=request.position,
        velocity=vec(request.velocity.x, request.velocity.y, -abs(request.velocity.z)),
        mass=request.mass - 0.5,
    )


def test_reset_episode_service(make_node, spin_until) -> None:
    served: list[ResetEpisode.Request] = []

    def handle(request, response):
        served.append(request)
        reply = expected_reset_response(request)
        for field in reply.get_fields_and_field_types():
            setattr(response, field, getattr(reply, field))
        return response

    server_node = make_node("reset_server")
    server_node.create_service(ResetEpisode, "/pd_test/sim/reset", handle)
    client_node = make_node("reset_client")
    client = client_node.create_client(ResetEpisode, "/pd_test/sim/reset")
    assert client.wait_for_service(timeout_sec=10.0), "service never became available"

    request = ResetEpisode.Request(
        use_initial_state=True,
        position=vec(1500.0, -250.5, 1999.875),
        velocity=vec(-75.0, 12.5, 90.0),
        mass=1905.0,
        seed=123_456_789_012,  # needs int64
    )
    future = client.call_async(request)
    assert spin_until(future.done, timeout_sec=10.0), "no response within 10 s"
    response = future.result()

    assert len(served) == 1
    assert served[0] == request
    assert response.success is True
    assert response.message == "episode started with seed 123456789012"
    assert response.episode == 41 + 123_456_789_012 % 7
    assert response.position == vec(1500.0, -250.5, 1999.875)
    assert response.velocity == vec(-75.0, 12.5, -90.0)
    assert response.mass == 1904.5
    assert response == expected_reset_response(request)


def expected_trajectory(request: ComputeTrajectory.Request) -> ComputeTrajectory.Response:
    n = request.control_points
    tof = 40.0 + request.mass / 1000.0
    control_times = [tof * i / (n - 1) for i in range(n)]
    steps = int(round(tof / 0.2)) + 1
    state_times = [0.2 * k for k in range(steps)]

    def lerp(a: float, t: float) -> float:
        return a * (1.0 - t / tof)

    p, v = request.position, request.velocity
    return ComputeTrajectory.Response(
        success=True,
        message=f"{request.method}/{request.objective}",
        time_of_flight=tof,
        fuel=request.mass * 0.1,
        solve_time=0.0123,
        cost=math.pi * 1e5,
        control_times=control_times,
        thrust=[vec(1e3 * math.sin(t), -1e3 * math.cos(t), 9e3 + t) for t in control_times],
        state_times=state_times,
        positions=[vec(lerp(p.x, t), lerp(p.y, t), lerp(p.z, t)) for t in state_times],
        velocities=[vec(lerp(v.x, t), lerp(v.y, t), lerp(v.z, t)) for t in state_times],
        masses=[request.mass - 0.5 * t for t in state_times],
        actions=[(13 * k) % 147 for k in range(steps)] if request.discretise else [],
        discrete_initial_position=vec(p.x + 1.0, p.y - 1.0, p.z),
        discrete_landed=request.discretise,
    )


def test_compute_trajectory_service(make_node, spin_until) -> None:
    def handle(request, response):
        reply = expected_trajectory(request)
        for field in reply.get_fields_and_field_types():
            setattr(response, field, getattr(reply, field))
        return response

    server_node = make_node("ocp_server")
    server_node.create_service(ComputeTrajectory, "/pd_test/ocp/compute_trajectory", handle)
    client_node = make_node("ocp_client")
    client = client_node.create_client(ComputeTrajectory, "/pd_test/ocp/compute_trajectory")
    assert client.wait_for_service(timeout_sec=10.0), "service never became available"

    request = ComputeTrajectory.Request(
        position=vec(1500.0, 300.0, 2000.0),
        velocity=vec(-75.0, -20.0, -90.0),
        mass=1905.0,
        method="slsqp",
        objective="energy",
        control_points=80,
        timeout=30.0,
        discretise=True,
    )
    future = client.call_async(request)
    assert spin_until(future.done, timeout_sec=10.0), "no response within 10 s"
    response = future.result()
    expected = expected_trajectory(request)

    assert response.success is True
    assert response.message == "slsqp/energy"
    assert len(response.control_times) == 80
    assert len(response.thrust) == 80
    assert len(response.actions) == len(response.state_times) == len(response.masses) > 200
    for field in expected.get_fields_and_field_types():
        got, want = getattr(response, field), getattr(expected, field)
        if isinstance(want, (list, tuple)) or hasattr(want, "typecode"):
            assert list(got) == list(want), field
        else:
            assert got == want, field
    assert response == expected
