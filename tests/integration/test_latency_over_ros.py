"""Latency over ROS: the simulator node flies every command two steps late (`delay_steps`), the
policy node identifies the delay from the lander's response, decides on the state each command
will meet, lands, and says which delay it found; the flight is the offline one to the bit."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import fly_shipped_policy_offline, fly_shipped_policy_over_ros

from pd_core.sim import Simulator
from pd_ros_common.convert import final_state

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.timeout(240)]

DELAY = 2
SEED = 12


def test_the_policy_node_identifies_a_two_step_delay_and_lands(tmp_path, make_node, spin_until):
    result, log = fly_shipped_policy_over_ros(
        tmp_path, make_node, spin_until, {"delay_steps": DELAY}, SEED
    )
    assert f"actuation delay {DELAY} step(s)" in log, log
    assert result.landed, result.reason
    assert result.rejected_commands == 0
    offline, policy = fly_shipped_policy_offline(Simulator(delay_steps=DELAY), SEED)
    assert policy.latency.delay_steps[0] == DELAY
    np.testing.assert_array_equal(final_state(result), offline)
