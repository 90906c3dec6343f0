"""The suite's DDS transport (conftest.py): UDP on loopback, no shared-memory ports.

A node process started by the suite (it inherits the suite's environment) must map no FastDDS
shared-memory port, or a participant SIGKILLed by a test could wedge later ones (conftest.py).
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

pytestmark = [pytest.mark.integration]

CHILD = """
import pathlib, rclpy
from std_msgs.msg import String
rclpy.init()
node = rclpy.create_node("transport_probe")
node.create_publisher(String, "transport_probe", 10)
maps = pathlib.Path("/proc/self/maps").read_text()
print("shm ports mapped:", sum("/dev/shm/fastdds_port" in line for line in maps.splitlines()))
node.destroy_node()
rclpy.shutdown()
"""


def shm_ports_mapped(env: dict[str, str]) -> str:
    """The child's report line, `shm ports mapped: N`, from a node started with `env`."""
    out = subprocess.run(
        [sys.executable, "-c", CHILD], env=env, capture_output=True, text=True, timeout=60
    )
    assert out.returncode == 0, out.stderr
    return out.stdout + out.stderr


def test_a_node_of_the_suite_maps_no_shared_memory_port():
    assert "shm ports mapped: 0" in shm_ports_mapped(dict(os.environ))


def test_without_the_profile_fastdds_maps_shared_memory_ports():
    """The check above can fail: rmw's LOCALHOST range adds the shared-memory transport."""
    env = {**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    env.pop("FASTDDS_DEFAULT_PROFILES_FILE")
    assert "shm ports mapped: 0" not in shm_ports_mapped(env)
