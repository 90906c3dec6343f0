"""Fixtures for tests that talk over ROS 2 / DDS.

ROS domain
----------
At import (before any ``rclpy.init``) this conftest claims a ROS domain id that no other pytest
session on this machine holds, and exports it as ``ROS_DOMAIN_ID``: the test process and every
node process it starts (they inherit ``os.environ``) share that domain, and two test runs at the
same time (or a demo on the default domain 0) never hear each other. A domain is claimed by an
exclusive ``flock`` held until the session ends (``pd_ros_common.domain.claim_domain_id``, shared
with ``pd_demo``).
Set ``PD_TEST_ROS_DOMAIN_ID=<id>`` to force one (for example to watch a test from another shell).

FastDDS is the RMW, also when pytest is run without ``source env.sh`` (rclpy must still be
importable then). Discovery and data stay on loopback, over UDP only: ``fastdds_udp_loopback.xml``
(the default participant profile, ``ROS_AUTOMATIC_DISCOVERY_RANGE=SYSTEM_DEFAULT`` so that rmw
applies it) is rmw_fastrtps's LOCALHOST set-up without its shared-memory transport. These tests
SIGKILL DDS participants on purpose (a recorder, a policy node), and a participant killed while it
holds a shared-memory port can leave that port's lock taken, so that a later participant blocks in
C, where no timeout reaches it (eProsima/Fast-DDS #1144, #5469). CI once hung past
pytest-timeout in the test after the one that kills a recorder. UDP carries the same messages
with the same QoS; only the copy path differs.

Fixtures
--------
``ros_context``  a fresh ``rclpy.Context``, initialised, shut down after the test;
``ros_executor`` a ``SingleThreadedExecutor`` on that context;
``make_node``    ``make_node(name, **kw)`` makes a ``Node`` on the context, adds it to the executor
                 and destroys it after the test;
``spin_until``   ``spin_until(predicate, timeout_sec=10.0) -> bool`` spins the executor with
                 ``spin_once`` steps until ``predicate()`` holds or the deadline passes
                 (never a bare ``spin``);
``service_ready`` ``service_ready(client, timeout_s=20.0) -> bool``: the server is discovered
                 and has had time to discover the client, so a first request is answered.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from pd_ros_common.domain import claim_domain_id

ROS_DOMAIN_ID, _domain_lock_fd = claim_domain_id("PD_TEST_ROS_DOMAIN_ID")
os.environ["ROS_DOMAIN_ID"] = str(ROS_DOMAIN_ID)
os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "SYSTEM_DEFAULT"
os.environ["FASTDDS_DEFAULT_PROFILES_FILE"] = str(
    Path(__file__).with_name("fastdds_udp_loopback.xml")
)
os.environ.pop("ROS_LOCALHOST_ONLY", None)

# After the environment is settled: rclpy reads it when a context is initialised.
import rclpy  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402

from pd_ros_common import session  # noqa: E402


def pytest_report_header(config: pytest.Config) -> str:
    env = ("ROS_DOMAIN_ID", "RMW_IMPLEMENTATION", "FASTDDS_DEFAULT_PROFILES_FILE")
    return " ".join(f"{k}={os.environ[k]}" for k in env)


@pytest.fixture
def ros_context() -> Iterator[Context]:
    context = Context()
    rclpy.init(context=context)
    try:
        yield context
    finally:
        context.try_shutdown()


@pytest.fixture
def ros_executor(ros_context: Context) -> Iterator[SingleThreadedExecutor]:
    executor = SingleThreadedExecutor(context=ros_context)
    try:
        yield executor
    finally:
        executor.shutdown(timeout_sec=2.0)


@pytest.fixture
def make_node(
    ros_context: Context, ros_executor: SingleThreadedExecutor
) -> Iterator[Callable[..., Node]]:
    nodes: list[Node] = []

    def factory(name: str, **kwargs) -> Node:
        node = Node(name, context=ros_context, **kwargs)
        nodes.append(node)
        ros_executor.add_node(node)
        return node

    try:
        yield factory
    finally:
        for node in reversed(nodes):
            ros_executor.remove_node(node)
            node.destroy_node()


@pytest.fixture
def spin_until(ros_executor: SingleThreadedExecutor) -> Callable[..., bool]:
    def spin(
        predicate: Callable[[], bool], timeout_sec: float = 10.0, step_sec: float = 0.05
    ) -> bool:
        return session.spin_until(ros_executor, predicate, timeout_sec, step_s=step_sec)

    return spin


@pytest.fixture
def service_ready(ros_executor: SingleThreadedExecutor) -> Callable[..., bool]:
    """``service_ready(client, timeout_s)``: the server is discovered and has had time to
    discover the client (`session.wait_for_server`), so a first request is answered."""

    def ready(client, timeout_s: float = 20.0) -> bool:
        return session.wait_for_server(ros_executor, client, timeout_s)

    return ready
