"""Helpers for integration tests that run the nodes as real processes (see conftest.py for the
ROS domain and the in-process rclpy fixtures).

Processes are started and stopped by `pd_ros_common.process.Supervisor` (here `ProcessSet`):
each in its own session (process group) with the test's environment (so the ROS_DOMAIN_ID
claimed by conftest.py), logging to a file, stopped by `stop_all` (SIGINT, then SIGKILL of the
whole group) in a `finally`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pd_core.config import TABLE3
from pd_interfaces.msg import EpisodeResult, LanderState, ThrustCommand
from pd_ros_common import qos
from pd_ros_common.process import Child as NodeProcess
from pd_ros_common.process import Supervisor as ProcessSet
from pd_ros_common.process import executable, ros_args, wait_for

__all__ = [
    "NodeProcess",
    "ProcessSet",
    "ROOT",
    "executable",
    "fly_shipped_policy_over_ros",
    "fly_shipped_policy_offline",
    "make_model",
    "offline_rollout",
    "ros_args",
    "table3_state",
    "wait_for",
]

START_S = 90.0  # node start-up deadline on a loaded 2-core machine (torch import)

ROOT = Path(__file__).resolve().parents[2]


def make_model(path: Path, seed: int = 0) -> Path:
    """An untrained (random) policy file: tests do not depend on the shipped model."""
    import torch

    from pd_core.dqn.network import QNetwork
    from pd_core.runtime.config import RuntimeConfig
    from pd_core.runtime.policy_file import save_policy

    torch.manual_seed(seed)
    return save_policy(path, QNetwork(), RuntimeConfig.off(), {"note": "untrained, for tests"})


def offline_rollout(model: Path, seed: int, initial_state: np.ndarray) -> list[np.ndarray]:
    """States [s0, s1, ...] of the pd_core rollout the simulator node must reproduce."""
    import pd_core
    from pd_core.env import PoweredDescentEnv

    policy = pd_core.load_policy(model)
    env = PoweredDescentEnv(disturbance=True)
    _, info = env.reset(seed=seed, options={"initial_state": initial_state})
    states = [info["state"]]
    policy.begin_episode()
    while True:
        _, _, term, trunc, info = env.step(policy.step(info["state"])[0])
        states.append(info["state"])
        if term or trunc:
            return states


def table3_state(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.uniform(TABLE3.lo, TABLE3.hi)


def fly_shipped_policy_offline(sim, seed: int, adapt=None):
    """(final true state, policy) of one episode of pd_core's `Simulator` `sim` flown in-process
    by the shipped policy (passed through `adapt`, if given) deciding online on the published
    (observed) state, as the node does."""
    from pd_core.commands import Command
    from pd_core.runtime.build import build

    policy = build().runtime  # the shipped policy, as the node finds it
    if adapt is not None:
        policy = adapt(policy)
    episode, _, _ = sim.reset(seed=seed)
    policy.begin_episode()
    while True:
        a, _ = policy.step(sim.observed_state)
        sim.submit(Command(episode, sim.step, a, tuple(float(v) for v in policy.thrust(a))))
        if sim.advance().done:
            return sim.state, policy


def fly_shipped_policy_over_ros(tmp_path: Path, make_node, spin_until, sim_params: dict, seed: int):
    """(EpisodeResult, policy node log) of one lockstep episode (seed `seed`) of a real
    pd_sim_node (`sim_params` added) and pd_policy_node in separate processes; the policy node
    has stopped (status 0) when this returns."""
    from pd_interfaces.msg import EpisodeResult
    from pd_interfaces.srv import ResetEpisode
    from pd_ros_common import qos
    from pd_ros_common.convert import reset_request

    procs = ProcessSet(tmp_path)
    try:
        sim = procs.node("pd_sim_node", {"lockstep": True, "start_episode": False, **sim_params})
        policy = procs.node("pd_policy_node", {})
        assert sim.wait_log("simulator ready", START_S), procs.logs()
        assert policy.wait_log("policy ready", START_S), procs.logs()
        probe = make_node("episode_probe")
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
        future = reset.call_async(reset_request(None, seed))
        assert spin_until(future.done, 20.0) and future.result().success
        episode = future.result().episode
        assert spin_until(lambda: any(r.episode == episode for r in results), 120.0)
        assert policy.stop() == 0, policy.log()
        return next(r for r in results if r.episode == episode), policy.log()
    finally:
        procs.stop_all()


class LoopListener:
    """What one probe node hears of the control loop: states, commands and episode results
    (each list appended to as messages arrive), on the stack's QoS."""

    def __init__(self, node) -> None:
        self.states: list[LanderState] = []
        self.commands: list[ThrustCommand] = []
        self.results: list[EpisodeResult] = []
        sub = node.create_subscription
        sub(LanderState, "/lander/state", self.states.append, qos.LOOP_SUB_QOS)
        sub(ThrustCommand, "/lander/thrust_cmd", self.commands.append, qos.LOOP_SUB_QOS)
        sub(EpisodeResult, "/lander/episode", self.results.append, qos.EPISODE_QOS)
