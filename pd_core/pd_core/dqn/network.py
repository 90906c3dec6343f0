"""Q-network of Sec. 3.2 / Table 2: 7 scaled inputs, tanh hidden layers, one output per action."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from pd_core.state import N_NEAR_PAD, NEAR_PAD_GAIN

ACTIVATIONS = {"tanh": nn.Tanh, "relu": nn.ReLU}
_FUNCTIONS = {"tanh": torch.tanh, "relu": F.relu}


class QNetwork(nn.Module):
    """MLP from scaled state (Eq. 20) to action values; (300, 200, 300) tanh in the paper.

    With `near_pad` (ours, off by default) the first layer also sees
    `pd_core.state.near_pad_features` of its input: a fixed, parameter-free transform, so the
    observation (Eq. 21) and the replay memories stay 7-wide. With `thrust_input` (ours, issue
    68) the observation has an 8th column, `pd_core.state.thrust_input` of the vertical thrust
    fraction the runtime layer counts on; the first layer sees [state, thrust, near-pad]."""

    def __init__(
        self,
        n_inputs: int = 7,
        n_actions: int = 147,
        hidden: tuple[int, ...] = (300, 200, 300),
        activation: str = "tanh",
        near_pad: bool = False,
        thrust_input: bool = False,
    ) -> None:
        super().__init__()
        if activation not in ACTIVATIONS:
            raise ValueError(f"activation must be one of {sorted(ACTIVATIONS)}, got {activation!r}")
        if near_pad and n_inputs < N_NEAR_PAD:
            raise ValueError(f"near_pad inputs need the 7 state inputs, got n_inputs={n_inputs}")
        layers: list[nn.Module] = []
        width = n_inputs + int(thrust_input) + (N_NEAR_PAD if near_pad else 0)
        for h in hidden:
            layers += [nn.Linear(width, h), ACTIVATIONS[activation]()]
            width = h
        layers.append(nn.Linear(width, n_actions))
        self.net = nn.Sequential(*layers)
        self._linears: list[nn.Linear] = [m for m in layers if isinstance(m, nn.Linear)]
        self._act = _FUNCTIONS[activation]
        self.n_inputs = n_inputs
        self.n_actions = n_actions
        self.hidden = tuple(hidden)
        self.activation = activation
        self.near_pad = near_pad
        self.thrust_input = thrust_input
        self.obs_width = n_inputs + int(thrust_input)
        """columns of an observation: the scaled state, then the thrust input if on"""
        self.register_buffer(
            "_near_pad_gain", torch.as_tensor(NEAR_PAD_GAIN, dtype=torch.float32), persistent=False
        )

    def inputs(self, obs: torch.Tensor) -> torch.Tensor:
        """What the first layer sees: the scaled state, then its near-pad features if on."""
        if not self.near_pad:
            return obs
        fine = torch.tanh(obs[..., :N_NEAR_PAD] * self._near_pad_gain)
        return torch.cat([obs, fine], dim=-1)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        """`self.net` on the inputs, each layer called as the function its module's forward
        is (`F.linear`, then the activation): the same arithmetic, to the bit, without the
        module-call machinery (hooks)."""
        h = self.inputs(obs)
        last = self._linears[-1]
        for lin in self._linears:
            h = F.linear(h, lin.weight, lin.bias)
            if lin is not last:
                h = self._act(h)
        return h

    def shape_metadata(self) -> dict:
        out = {
            "n_inputs": self.n_inputs,
            "n_actions": self.n_actions,
            "hidden": list(self.hidden),
            "activation": self.activation,
        }
        if self.near_pad:  # absent in files without them: their metadata is unchanged
            out["near_pad"] = True
        if self.thrust_input:
            out["thrust_input"] = True
        return out

    def widened_from(self, other: QNetwork) -> None:
        """Copy `other`'s weights; near-pad or thrust inputs it lacks start with zero weight, so
        the values are `other`'s exactly until training moves them (fine-tuning a paper network,
        or a 7-input network given the thrust input)."""
        extras = ("near_pad", "thrust_input")
        same = {k: v for k, v in other.shape_metadata().items() if k not in extras}
        mine = {k: v for k, v in self.shape_metadata().items() if k not in extras}
        lost = [k for k in extras if getattr(other, k) and not getattr(self, k)]
        if same != mine or lost:
            raise ValueError(f"cannot widen {other.shape_metadata()} to {self.shape_metadata()}")
        state = other.state_dict()
        w = state["net.0.weight"]
        zero = torch.zeros(w.shape[0], 1, dtype=w.dtype)
        n = other.n_inputs
        cols = [w[:, :n]]
        if self.thrust_input:
            cols.append(w[:, n : n + 1] if other.thrust_input else zero)
        if self.near_pad:
            near = w[:, other.obs_width :] if other.near_pad else zero.repeat(1, N_NEAR_PAD)
            cols.append(near)
        state["net.0.weight"] = torch.cat(cols, dim=1)
        self.load_state_dict(state)
