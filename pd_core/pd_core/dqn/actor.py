"""Greedy actions of a live Q-network (training's periodic evaluation, tests).

A policy *file* flies through `pd_core.runtime.load_policy` (numpy, no torch). This actor is for
a `QNetwork` object in memory; put it behind the runtime layer with
`pd_core.runtime.Runtime(TorchGreedy(net), config)` to evaluate it as it will fly.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from pd_core.dqn.network import QNetwork
from pd_core.state import scale_state


def network_kwargs(shape: dict[str, Any]) -> dict[str, Any]:
    """`QNetwork` arguments of a policy file's "network" metadata."""
    return {
        "n_inputs": int(shape["n_inputs"]),
        "n_actions": int(shape["n_actions"]),
        "hidden": tuple(shape["hidden"]),
        "activation": shape["activation"],
        "near_pad": bool(shape.get("near_pad", False)),
    }


class TorchGreedy:
    """Greedy actions (B,) of a Q-network on physical states (B, 7): the network alone."""

    def __init__(self, net: QNetwork) -> None:
        self.net = net
        self.name = "network"

    def act_batch(self, states: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            device = next(self.net.parameters()).device
            q = self.net(torch.from_numpy(scale_state(states)).to(device))
        return q.argmax(dim=1).cpu().numpy()
