"""Navigation noise over ROS: the simulator node publishes states with 3 m / 0.3 m/s of white
noise (`nav_position_sigma_m`, `nav_velocity_sigma_mps`), the policy node learns the noise,
flies its filtered estimate, lands, and says so; the flight is the offline one to the bit. The
node, given no model_path, flies the shipped optimal-control student."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import fly_shipped_policy_offline, fly_shipped_policy_over_ros

from pd_core.runtime.policy_file import SHIPPED_POLICY
from pd_core.sim import Simulator
from pd_ros_common.convert import final_state

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.timeout(240)]

SIGMA = (3.0, 0.3)
SEED = 14


def test_the_policy_node_filters_noisy_navigation_and_lands(tmp_path, make_node, spin_until):
    noise = {"nav_position_sigma_m": SIGMA[0], "nav_velocity_sigma_mps": SIGMA[1]}
    result, log = fly_shipped_policy_over_ros(tmp_path, make_node, spin_until, noise, SEED)
    assert "navigation filter on (noise" in log, log
    assert f"{SHIPPED_POLICY.name} (network" in log, log  # no model_path: the shipped file
    assert result.landed, result.reason
    assert result.rejected_commands == 0
    offline, policy = fly_shipped_policy_offline(Simulator(nav_sigma=SIGMA), SEED)
    assert policy.latency.nav.engaged[0]
    np.testing.assert_array_equal(final_state(result), offline)
