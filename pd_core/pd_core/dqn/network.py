"""Q-network of Sec. 3.2 / Table 2: 7 scaled inputs, tanh hidden layers, one output per action."""

from __future__ import annotations

import torch
from torch import nn

ACTIVATIONS = {"tanh": nn.Tanh, "relu": nn.ReLU}


class QNetwork(nn.Module):
    """MLP from scaled state (Eq. 20) to action values; (300, 200, 300) tanh in the paper."""

    def __init__(
        self,
        n_inputs: int = 7,
        n_actions: int = 147,
        hidden: tuple[int, ...] = (300, 200, 300),
        activation: str = "tanh",
    ) -> None:
        super().__init__()
        if activation not in ACTIVATIONS:
            raise ValueError(f"activation must be one of {sorted(ACTIVATIONS)}, got {activation!r}")
        layers: list[nn.Module] = []
        width = n_inputs
        for h in hidden:
            layers += [nn.Linear(width, h), ACTIVATIONS[activation]()]
            width = h
        layers.append(nn.Linear(width, n_actions))
        self.net = nn.Sequential(*layers)
        self.n_inputs = n_inputs
        self.n_actions = n_actions
        self.hidden = tuple(hidden)
        self.activation = activation

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.net(obs)

    def shape_metadata(self) -> dict:
        return {
            "n_inputs": self.n_inputs,
            "n_actions": self.n_actions,
            "hidden": list(self.hidden),
            "activation": self.activation,
        }
