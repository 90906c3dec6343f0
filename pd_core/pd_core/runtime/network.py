"""The Q-network's forward pass in numpy: what flies needs no torch at decision time."""

from __future__ import annotations

import re
from collections.abc import Mapping

import numpy as np

from pd_core.runtime.kernels import states_valid
from pd_core.runtime.kernels_step import network_inputs
from pd_core.state import NEAR_PAD_GAIN, STATE_LIMITS, as_state_rows, check_state, thrust_input

_LAYER = re.compile(r"^net\.(\d+)\.(weight|bias)$")
_NO_GAIN = np.zeros(0)


def observed_states(states: np.ndarray) -> np.ndarray:
    """States (B, 7) as floats, or `check_state`'s ValueError saying what is wrong with them:
    the compiled check (`kernels.states_valid`) first, `check_state`'s message only when it
    fails (a decision pays microseconds, not `check_state`'s dozen numpy calls)."""
    s = as_state_rows(states)
    if states_valid(s, STATE_LIMITS):
        return s
    return check_state(states).reshape(-1, 7)


class NumpyQNetwork:
    """Greedy actions of a fully connected Q-network (`pd_core.dqn.network.QNetwork`'s layout:
    `net.<i>.weight` (out, in) and `net.<i>.bias`) on physical states (B, 7), SI: the inputs are
    scaled by `state_scale` (Eqs. 20-21), with the near-pad features where the network has them,
    and the layers run in `dtype`.

    A network with the thrust input (`thrust_input`, issue 68) also sees
    `pd_core.state.thrust_input` of the vertical thrust fraction the runtime layer counts on:
    `Runtime.step_rows` hands it over (`take_thrust_fraction`) before each `act_batch`, which
    uses it once; an `act_batch` without it, and `propose` (`Runtime.bare_action`), see a nominal
    engine. It keeps no memory between steps (`begin_episode` has nothing to forget)."""

    def __init__(
        self,
        tensors: Mapping[str, np.ndarray],
        state_scale: np.ndarray,
        activation: str = "tanh",
        near_pad: bool = False,
        dtype: str = "float32",
        thrust_input: bool = False,
    ) -> None:
        found = sorted(
            {int(m.group(1)) for k in tensors if (m := _LAYER.match(k))},
        )
        if not found:
            raise ValueError("no layers named net.<i>.weight / net.<i>.bias")
        self.dtype = np.dtype(dtype)
        self.layers = [
            (
                np.ascontiguousarray(np.asarray(tensors[f"net.{i}.weight"]).T, dtype=self.dtype),
                np.asarray(tensors[f"net.{i}.bias"], dtype=self.dtype),
            )
            for i in found
        ]
        self.scale = np.asarray(state_scale, dtype=float)
        self.near_pad = near_pad
        self._near_gain = NEAR_PAD_GAIN if near_pad else _NO_GAIN
        self.activation = activation
        self.n_actions = self.layers[-1][1].shape[0]
        self.takes_thrust_fraction = thrust_input
        self._fraction: np.ndarray | None = None

    def take_thrust_fraction(self, fraction: np.ndarray) -> None:
        """The fraction (B,) the layer counts on for the rows of the next `act_batch`."""
        self._fraction = np.asarray(fraction, dtype=float).reshape(-1)

    def q_values(self, states: np.ndarray) -> np.ndarray:
        """Action values (B, n_actions) of physical states (B, 7), with the thrust fraction
        handed over for them (`take_thrust_fraction`, used up here); ValueError if invalid."""
        fraction, self._fraction = self._fraction, None
        return self._forward(states, fraction)

    def _forward(self, states: np.ndarray, fraction: np.ndarray | None) -> np.ndarray:
        """Action values (B, n_actions) of physical states (B, 7) with the vertical thrust
        fraction (B,) counted on (None or another length: a nominal engine). The inputs
        (scaling, validation and the near-pad features' arguments) are one compiled call
        (`kernels_step.network_inputs`); the tanh and the layers are numpy's."""
        s = as_state_rows(states)
        b, k = len(s), len(self._near_gain)
        scaled, near = np.empty((b, 7)), np.empty((b, k))
        if not network_inputs(s, STATE_LIMITS, self.scale, self._near_gain, scaled, near):
            check_state(states)
        t = int(self.takes_thrust_fraction)
        h = np.empty((b, 7 + t + k), dtype=self.dtype)
        h[:, :7] = scaled
        if t:
            h[:, 7] = 0.0 if fraction is None or len(fraction) != b else thrust_input(fraction)
        if k:
            h[:, 7 + t :] = np.tanh(near)
        last = len(self.layers) - 1
        for i, (w, b) in enumerate(self.layers):
            h = h @ w
            h += b
            if i < last:
                h = np.tanh(h, out=h) if self.activation == "tanh" else np.maximum(h, 0.0, out=h)
        return h

    def act_batch(self, states: np.ndarray) -> np.ndarray:
        """Greedy actions (B,) of physical states (B, 7): the network alone."""
        return self.q_values(states).argmax(axis=-1)

    def propose(self, states: np.ndarray) -> np.ndarray:
        """Greedy actions (B,) on a nominal engine, changing nothing (a fraction handed over
        stays for the next `act_batch`): `Runtime.bare_action`."""
        return self._forward(states, None).argmax(axis=-1)

    def begin_episode(self) -> None:
        """A new episode: nothing to forget (the network decides on the state alone)."""
