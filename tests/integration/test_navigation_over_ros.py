"""Navigation noise over ROS: the simulator node publishes states with 3 m / 0.3 m/s of white
noise (`nav_position_sigma_m`, `nav_velocity_sigma_mps`), the policy node learns the noise,
flies its filtered estimate, lands, and says so; the flight is the offline one to the bit."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import ProcessSet

from pd_core.policy import load_policy
from pd_core.sim import Command, Simulator
from pd_interfaces.msg import EpisodeResult
from pd_interfaces.srv import ResetEpisode
from pd_policy_node.node import default_model_path
from pd_ros_common import qos
from pd_ros_common.convert import final_state, reset_request

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.timeout(240)]

START_S = 90.0  # node start-up deadline on a loaded 2-core machine (torch import)
SIGMA = (3.0, 0.3)
SEED = 14


def offline(seed: int) -> np.ndarray:
    """Final true state of the same episode flown in-process: pd_core's simulator with the same
    noise, the shipped policy deciding online on the published (noisy) state as the node does."""
    policy = load_policy(default_model_path())
    sim = Simulator(nav_sigma=SIGMA)
    episode, _, _ = sim.reset(seed=seed)
    policy.begin_episodes(1)
    while True:
        a = policy.act_online(sim.observed_state)
        sim.submit(Command(episode, sim.step, a, tuple(float(v) for v in policy.thrust(a))))
        if sim.advance().done:
            assert policy.latency.nav.engaged[0]
            return sim.state


def test_the_policy_node_filters_noisy_navigation_and_lands(tmp_path, make_node, spin_until):
    procs = ProcessSet(tmp_path)
    try:
        sim = procs.node(
            "pd_sim_node",
            {
                "lockstep": True,
                "autostart": False,
                "nav_position_sigma_m": SIGMA[0],
                "nav_velocity_sigma_mps": SIGMA[1],
            },
        )
        policy = procs.node("pd_policy_node", {})
        assert sim.wait_log("simulator ready", START_S), procs.logs()
        assert policy.wait_log("policy ready", START_S), procs.logs()
        probe = make_node("navigation_probe")
        results: list[EpisodeResult] = []
        probe.create_subscription(EpisodeResult, "/lander/episode", results.append, qos.EPISODE_QOS)
        reset = probe.create_client(ResetEpisode, "/sim/reset")
        assert spin_until(reset.service_is_ready, 20.0)
        assert spin_until(
            lambda: (
                probe.count_subscribers("/lander/state") >= 1
                and probe.count_publishers("/lander/thrust_cmd") >= 1
            ),
            30.0,
        )
        spin_until(lambda: False, 0.5)
        future = reset.call_async(reset_request(None, SEED))
        assert spin_until(future.done, 20.0) and future.result().success
        episode = future.result().episode
        assert spin_until(lambda: any(r.episode == episode for r in results), 120.0)
        assert policy.stop() == 0, policy.log()
        assert "navigation filter on (noise" in policy.log(), policy.log()
        result = next(r for r in results if r.episode == episode)
        assert result.landed, result.reason
        assert result.rejected_commands == 0
        np.testing.assert_array_equal(final_state(result), offline(SEED))
    finally:
        procs.stop_all()
