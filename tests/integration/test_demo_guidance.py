"""`make demo`'s main job, run as users run it (`pd_demo --fast`): the bag holds one
GuidanceStatus per command, and who decided, counted in the bag, equals the policy node's own
statistics line. Without --model it flies, and names, the shipped policy file; with --objective
fuel it sets the flight beside the fuel-optimal landing."""

from __future__ import annotations

import os
import subprocess

import pytest
from helpers import executable

from pd_bringup.bag import read_bag
from pd_bringup.guidance import bag_counts, node_counts
from pd_core.runtime.policy_file import SHIPPED_POLICY

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.timeout(240)]


def test_the_demo_bag_says_who_decided_each_command_as_the_node_counts(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "ROS_DOMAIN_ID"}  # it claims its own
    out = subprocess.run(
        [
            executable("pd_bringup", "pd_demo"),
            "--fast",
            "--objective",
            "fuel",
            "--out",
            str(tmp_path),
        ],
        env=env,
        capture_output=True,
        text=True,
        timeout=200,
        check=False,
    )
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    bag = tmp_path / "bag"
    topics = [t for t, _, _ in read_bag(bag).messages]
    commands = topics.count("/lander/thrust_cmd")
    assert commands > 100 and topics.count("/lander/guidance_status") == commands
    in_bag = bag_counts(bag)
    assert sum(in_bag.values()) == commands
    log = (tmp_path / "logs" / "pd_policy_node.log").read_text()
    assert node_counts(log) == in_bag, log[-2000:]
    assert "equal to the policy node's count" in out.stdout, out.stdout[-2000:]
    flown = next(x for x in out.stdout.splitlines() if x.startswith("  policy: "))[10:]
    assert flown.endswith(str(SHIPPED_POLICY)) and f"policy ready: {flown} (" in log, flown
    fuel = next(x for x in out.stdout.splitlines() if x.startswith("  fuel "))
    # the fuel-optimal landing burns less than any guidance flown on 0.2 s steps
    ratio = float(fuel.split("(")[-1].split("%")[0])
    assert "vs OCP (fuel)" in fuel and 0.0 < ratio < 20.0, fuel
