"""An engine out of spec over ROS: the simulator node's thrusters deliver 88 % of each command
(`thrust_scale`); the policy node measures the shortfall, brakes on what the engine delivers,
lands, and says so. The flight is the offline one to the bit, and offline, counting on the
nominal thrust (`measured_thrust` 0), the same episode is lost."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import fly_shipped_policy_offline, fly_shipped_policy_over_ros

from pd_core.runtime.layer import Runtime
from pd_core.sim import Simulator
from pd_ros_common.convert import final_state

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.timeout(240)]

SCALE = 0.88
SEED = 0  # an episode the nominal-thrust layer loses with the shipped file (6 m/s)


def nominal_thrust(p: Runtime) -> Runtime:
    """The same runtime counting on the nominal thrust."""
    config = p.config.with_settings("measured_thrust=0")
    return Runtime(p.actor, config, p.actions, p.name, p.metadata)


def test_the_policy_node_brakes_on_the_thrust_it_measures_and_lands(
    tmp_path, make_node, spin_until
):
    result, log = fly_shipped_policy_over_ros(
        tmp_path, make_node, spin_until, {"thrust_scale": SCALE}, SEED
    )
    assert "vertical thrust 88 % of nominal" in log, log
    assert result.landed, result.reason
    assert result.rejected_commands == 0
    offline, policy = fly_shipped_policy_offline(Simulator(thrust_scale=SCALE), SEED)
    np.testing.assert_allclose(
        policy.latency.vertical_thrust_scale(np.array([0])), SCALE, atol=0.01
    )
    np.testing.assert_array_equal(final_state(result), offline)
    nominal, _ = fly_shipped_policy_offline(Simulator(thrust_scale=SCALE), SEED, nominal_thrust)
    assert not (np.linalg.norm(nominal[0:2]) < 5.0 and np.linalg.norm(nominal[3:6]) < 2.0)
