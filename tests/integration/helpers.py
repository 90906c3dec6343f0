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
from pd_ros_common.process import Child as NodeProcess
from pd_ros_common.process import Supervisor as ProcessSet
from pd_ros_common.process import executable, ros_args, wait_for

__all__ = [
    "NodeProcess",
    "ProcessSet",
    "ROOT",
    "executable",
    "make_model",
    "offline_rollout",
    "ros_args",
    "table3_state",
    "wait_for",
]

ROOT = Path(__file__).resolve().parents[2]


def make_model(path: Path, seed: int = 0) -> Path:
    """An untrained (random) policy file: tests do not depend on the shipped model."""
    import torch

    from pd_core.dqn.network import QNetwork
    from pd_core.policy import save_policy

    torch.manual_seed(seed)
    return save_policy(path, QNetwork(), {"note": "untrained, for tests"})


def offline_rollout(model: Path, seed: int, initial_state: np.ndarray) -> list[np.ndarray]:
    """States [s0, s1, ...] of the pd_core rollout the simulator node must reproduce."""
    import pd_core
    from pd_core.env import PoweredDescentEnv

    policy = pd_core.load_policy(model)
    env = PoweredDescentEnv(disturbance=True)
    _, info = env.reset(seed=seed, options={"initial_state": initial_state})
    states = [info["state"]]
    while True:
        _, _, term, trunc, info = env.step(policy.act(info["state"]))
        states.append(info["state"])
        if term or trunc:
            return states


def table3_state(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.uniform(TABLE3.lo, TABLE3.hi)
