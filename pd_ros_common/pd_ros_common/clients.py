"""Service clients of the stack's services, with the QoS a burst of requests needs.

A service client's QoS decides what a burst loses: its responses arrive on a KEEP_LAST reader of
the client's depth, so with rclpy's default service QoS (depth 10) the answers to a burst of more
than 10 requests overwrite each other before the client takes them (7 of 20 and 36 of 50 were
never answered). The stack's servers keep `qos.SERVICE_DEPTH` (200) requests and responses, and
a client needs the same depth to get an answer to every request of a burst that size: these
clients have it (`qos.SERVICE_QOS`: RELIABLE, VOLATILE, KEEP_LAST 200).
"""

from __future__ import annotations

from typing import Any

from rclpy.client import Client
from rclpy.node import Node

from pd_interfaces.srv import ComputeTrajectory, ResetEpisode
from pd_ros_common import names, qos


def ocp_client(node: Node, name: str = names.OCP_SERVICE, **kwargs: Any) -> Client:
    """A client of ocp/compute_trajectory (relative: in `node`'s namespace) whose bursts of up
    to `qos.SERVICE_DEPTH` requests are answered in full (`kwargs`: e.g. callback_group)."""
    return node.create_client(ComputeTrajectory, name, qos_profile=qos.SERVICE_QOS, **kwargs)


def reset_client(node: Node, name: str = names.RESET_SERVICE, **kwargs: Any) -> Client:
    """A client of sim/reset with the stack's service QoS (as `ocp_client`)."""
    return node.create_client(ResetEpisode, name, qos_profile=qos.SERVICE_QOS, **kwargs)
