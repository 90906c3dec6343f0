"""pd_policy_node's `controller` parameter: a reference controller of pd_core flies the lander over
ROS in lockstep, exactly as it flies offline (issue 10 item 5); so does the DQN behind the runtime
layer (`layer` parameter), and a reference controller behind it with layer "always" (also given
by the parameter's deprecated old name, `shield`)."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import LoopListener, ProcessSet

from pd_core.env import PoweredDescentEnv
from pd_core.runtime.build import build
from pd_interfaces.srv import ResetEpisode
from pd_ros_common.convert import final_state, reset_request

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.timeout(240)]

START_S = 90.0  # node start-up deadline on a loaded 2-core machine (torch import)
MPC_STEPS = 10  # an MPC teacher re-plans every step: fly this many, not a whole episode


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    procs = ProcessSet(tmp_path_factory.mktemp("controllers"))
    try:
        node = procs.node("pd_sim_node", {"lockstep": True, "start_episode": False})
        assert node.wait_log("simulator ready", START_S), procs.logs()
        yield procs
    finally:
        procs.stop_all()


class Loop:
    def __init__(self, make_node, spin_until):
        self.node = make_node("controller_probe")
        self.spin_until = spin_until
        heard = LoopListener(self.node)
        self.states, self.commands, self.results = heard.states, heard.commands, heard.results
        self.reset_cli = self.node.create_client(ResetEpisode, "/sim/reset")
        assert spin_until(self.reset_cli.service_is_ready, 20.0)

    def fly(
        self, procs: ProcessSet, controller: str, seed: int, **params: str
    ) -> tuple[int, object]:
        """Start a policy node with `controller` (the only one) and an episode; (episode, node)."""
        name = "-".join([controller, *params.values()])
        policy = procs.node("pd_policy_node", {"controller": controller, **params}, name=name)
        assert policy.wait_log("policy ready", START_S), policy.log()
        n = self.node
        assert self.spin_until(
            lambda: (
                n.count_publishers("/lander/thrust_cmd") >= 1
                and n.count_subscribers("/lander/state") >= 2
            ),
            30.0,
        )
        self.spin_until(lambda: False, 0.5)
        future = self.reset_cli.call_async(reset_request(None, seed))
        assert self.spin_until(future.done, 20.0) and future.result().success
        return future.result().episode, policy


def offline(
    controller: str, seed: int, steps: int | None = None, layer: str = "always"
) -> list[np.ndarray]:
    # what the node builds for these parameters (the shipped file for "dqn")
    spec = "" if controller == "dqn" else f"controller:{controller}"
    ctl = build(spec, layer=layer, as_runtime=True).runtime
    env = PoweredDescentEnv(disturbance=True)
    _, info = env.reset(seed=seed)
    states = [info["state"]]
    ctl.begin_episode()
    while steps is None or len(states) <= steps:
        _, _, term, trunc, info = env.step(ctl.step(info["state"])[0])
        states.append(info["state"])
        if term or trunc:
            break
    return states


@pytest.mark.parametrize(
    ("name", "parameter", "layer"),
    [
        ("zemzev", "layer", "file"),
        ("zemzev", "layer", "always"),
        ("zemzev-vernier", "shield", "always"),  # the deprecated old name: it warns, and flies
    ],
)
def test_zemzev_flies_over_ros_as_offline(sim, make_node, spin_until, name, parameter, layer):
    """layer "always" puts the reference controller behind the runtime layer, as offline."""
    loop = Loop(make_node, spin_until)
    episode, policy = loop.fly(sim, name, seed=8, **{parameter: layer})
    assert spin_until(lambda: any(r.episode == episode for r in loop.results), 120.0)
    assert policy.stop() == 0, policy.log()
    assert ("runtime layer on" in policy.log()) == (layer == "always")
    deprecated = "parameter shield is deprecated, use layer: 'always' is flown as layer"
    assert (deprecated in policy.log()) == (parameter == "shield"), policy.log()
    result = next(r for r in loop.results if r.episode == episode)
    expected = offline(name, 8, layer=layer)
    assert result.landed, result.reason
    assert result.steps == len(expected) - 1 and result.rejected_commands == 0
    np.testing.assert_array_equal(final_state(result), expected[-1])


def test_dqn_behind_the_layer_flies_over_ros_as_offline(sim, make_node, spin_until):
    loop = Loop(make_node, spin_until)
    episode, policy = loop.fly(sim, "dqn", seed=11, layer="always")
    assert spin_until(lambda: any(r.episode == episode for r in loop.results), 120.0)
    assert policy.stop() == 0, policy.log()
    assert "runtime layer on, config " in policy.log(), policy.log()
    assert "layer changed " in policy.log(), policy.log()
    result = next(r for r in loop.results if r.episode == episode)
    expected = offline("dqn", 11)
    assert result.landed, result.reason
    assert result.steps == len(expected) - 1 and result.rejected_commands == 0
    np.testing.assert_array_equal(final_state(result), expected[-1])


def test_mpc_fuel_flies_over_ros(sim, make_node, spin_until):
    """The MPC teacher answers every state with a valid command (it re-plans every step, so
    only its first steps are flown; its plans depend on solver time limits, so the states are
    not compared with an offline run)."""
    loop = Loop(make_node, spin_until)
    sim_node = sim.children[0]
    before = len(sim_node.log())
    episode, policy = loop.fly(sim, "mpc-fuel", seed=9)

    def answered() -> set[int]:
        return {c.step for c in loop.commands if c.episode == episode}

    def flown() -> set[int]:
        return {s.step for s in loop.states if s.episode == episode}

    # every step answered and its state heard (the states come from another writer: they may
    # lag the commands in this probe)
    want = set(range(MPC_STEPS))
    assert spin_until(lambda: want <= answered() and want <= flown(), 180.0), (
        sorted(answered()),
        sorted(flown()),
    )
    assert policy.stop() == 0, policy.log()
    assert "command rejected" not in sim_node.log()[before:], sim_node.log()[before:]
