"""Greedy actor of a live Q-network (training's periodic evaluation, tests).

A policy *file* needs no torch to fly: `pd_core.policy.load_policy` returns a `Policy` whose
`act_batch` runs numpy copies of the layers. This actor is for a `QNetwork` object in memory.
"""

from __future__ import annotations

import numpy as np
import torch

from pd_core.actions import DEFAULT_ACTIONS
from pd_core.dqn.network import QNetwork
from pd_core.latency import CompensatesLatency
from pd_core.shield import ShieldParams, latency_for, shield_actions
from pd_core.state import scale_state


class NetActor(CompensatesLatency):
    """Greedy actions of a Q-network on physical states (`pd_core.evaluate.Actor`), behind the
    braking shield if given one, with its latency compensation (training evaluates the policy
    as it will fly)."""

    def __init__(self, net: QNetwork, shield: ShieldParams | None = None) -> None:
        self.net = net
        self.shield = shield
        self.actions = DEFAULT_ACTIONS
        self.latency = latency_for(shield)

    def act_batch(
        self, states: np.ndarray, vertical_thrust_scale: np.ndarray | None = None
    ) -> np.ndarray:
        with torch.no_grad():
            q = self.net(torch.from_numpy(scale_state(states)))
        greedy = q.argmax(dim=1).numpy()
        if self.shield is None:
            return greedy
        shielded, _ = shield_actions(
            greedy, states, DEFAULT_ACTIONS, self.shield, vertical_thrust_scale
        )
        return shielded
