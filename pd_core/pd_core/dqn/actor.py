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
from pd_core.state import scale_state, thrust_input


def network_kwargs(shape: dict[str, Any]) -> dict[str, Any]:
    """`QNetwork` arguments of a policy file's "network" metadata."""
    return {
        "n_inputs": int(shape["n_inputs"]),
        "n_actions": int(shape["n_actions"]),
        "hidden": tuple(shape["hidden"]),
        "activation": shape["activation"],
        "near_pad": bool(shape.get("near_pad", False)),
        "thrust_input": bool(shape.get("thrust_input", False)),
    }


class TorchGreedy:
    """Greedy actions (B,) of a Q-network on physical states (B, 7): the network alone. A
    network with the thrust input takes the fraction the runtime layer counts on
    (`take_thrust_fraction`, before each `act_batch`, as `NumpyQNetwork`); without one, nominal."""

    def __init__(self, net: QNetwork) -> None:
        self.net = net
        self.name = "network"
        self.takes_thrust_fraction = bool(getattr(net, "thrust_input", False))
        self._fraction: np.ndarray | None = None

    def take_thrust_fraction(self, fraction: np.ndarray) -> None:
        self._fraction = np.asarray(fraction, dtype=float).reshape(-1)

    def act_batch(self, states: np.ndarray) -> np.ndarray:
        obs = scale_state(np.asarray(states, dtype=float).reshape(-1, 7))
        if self.takes_thrust_fraction:
            f, self._fraction = self._fraction, None
            frac = f if f is not None and len(f) == len(obs) else np.ones(len(obs))
            obs = np.concatenate([obs, thrust_input(frac)[:, None]], axis=1)
        with torch.no_grad():
            device = next(self.net.parameters()).device
            q = self.net(torch.from_numpy(obs).to(device))
        return q.argmax(dim=1).cpu().numpy()
