"""Trained policies on disk: `save_policy` writes them, `load_policy` checks and loads them.

A policy is two files: `<name>.pt` (the Q-network's tensors, read with
`torch.load(weights_only=True)` so a model file cannot run code) and `<name>.json` (metadata:
network shape, action discretisation, thrust limits, state scaling, dt, training config, seed, code
version). A file whose metadata disagrees with this code is refused with the difference named.
"""

from __future__ import annotations

import json
import math
import re
import subprocess
from pathlib import Path
from typing import Any

import numpy as np

from pd_core.actions import ActionSpace
from pd_core.config import DT_S, N_ACTIONS_PER_AXIS, RL_THRUST, STATE_SCALE, ThrustLimits
from pd_core.latency import CompensatesLatency
from pd_core.shield import ShieldParams, latency_for, shield_actions
from pd_core.state import check_state, near_pad_features

FORMAT_VERSION = 1
SHIELD_MODES = ("file", "always", "never")
"""`load_policy(shield=...)`: as the metadata says, always, never"""


class PolicyLoadError(ValueError):
    """A policy file is missing, unreadable or does not match the code."""


def code_version() -> str:
    """`git describe` of the source tree, or 'unknown' outside a checkout."""
    try:
        out = subprocess.run(
            ["git", "describe", "--always", "--dirty"],
            check=False,
            cwd=Path(__file__).resolve().parent,
            capture_output=True,
            text=True,
            timeout=5,
        )
        return out.stdout.strip() or "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def expected_metadata() -> dict[str, Any]:
    """The parts of the metadata that must equal the code's config for a file to load."""
    return {
        "format_version": FORMAT_VERSION,
        "n_per_axis": list(N_ACTIONS_PER_AXIS),
        "thrust_min_n": list(RL_THRUST.min_n),
        "thrust_max_n": list(RL_THRUST.max_n),
        "state_scale": STATE_SCALE.tolist(),
        "dt_s": DT_S,
    }


def paths_for(path: str | Path) -> tuple[Path, Path]:
    """(weights .pt, metadata .json) for a path given with either suffix or none."""
    p = Path(path)
    stem = p.with_suffix("") if p.suffix in (".pt", ".json") else p
    return stem.with_suffix(".pt"), stem.with_suffix(".json")


def save_policy(
    path: str | Path, network: Any, extra_metadata: dict[str, Any] | None = None
) -> Path:
    """Write `network` (a QNetwork) and its metadata; returns the .pt path."""
    import torch

    pt, js = paths_for(path)
    pt.parent.mkdir(parents=True, exist_ok=True)
    meta = {
        **expected_metadata(),
        "network": network.shape_metadata(),
        "code_version": code_version(),
    }
    meta.update(extra_metadata or {})
    state = {k: v.detach().cpu().contiguous() for k, v in network.state_dict().items()}
    torch.save(state, pt)
    js.write_text(json.dumps(meta, indent=2, sort_keys=True, default=str) + "\n")
    return pt


def _close(a: Any, b: Any) -> bool:
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_close(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return math.isclose(a, b, rel_tol=1e-12, abs_tol=0.0)
    return a == b


class Policy(CompensatesLatency):
    """Greedy policy of a trained Q-network, on physical states [x, y, z, vx, vy, vz, m] (SI),
    behind the braking shield (`pd_core.shield`) if given one (`load_policy` decides), and then
    with the latency compensation it asks for (`act_rows`, `act_online`: `pd_core.latency`)."""

    def __init__(
        self, network: Any, metadata: dict[str, Any], shield: ShieldParams | None = None
    ) -> None:
        self.network = network.eval()
        self.metadata = metadata
        self.actions = ActionSpace(
            tuple(metadata["n_per_axis"]),
            ThrustLimits(tuple(metadata["thrust_min_n"]), tuple(metadata["thrust_max_n"])),
        )
        self._scale = np.asarray(metadata["state_scale"], dtype=float)
        # numpy copy of the layers: one 7-vector is 3-5x faster here than through torch.
        self._layers = [
            (
                m.weight.detach().numpy().astype(np.float64).T,
                m.bias.detach().numpy().astype(np.float64),
            )
            for m in network.net
            if hasattr(m, "weight")
        ]
        self._act_fn = np.tanh if metadata["network"]["activation"] == "tanh" else _relu
        self._near_pad = bool(metadata["network"].get("near_pad", False))
        self.shield = shield
        self.shield_fired = 0
        """steps on which the shield overrode the network (counted since loading)"""
        self.latency = latency_for(shield)

    def q_values(self, state: np.ndarray) -> np.ndarray:
        """Action values (..., n_actions) of physical states (..., 7); ValueError if invalid."""
        h = check_state(state) * self._scale
        if self._near_pad:
            h = np.concatenate([h, near_pad_features(h)], axis=-1)
        for i, (w, b) in enumerate(self._layers):
            h = h @ w + b
            if i < len(self._layers) - 1:
                h = self._act_fn(h)
        return h

    def act(self, state: np.ndarray) -> int:
        """Greedy action index for one physical state (7,)."""
        return int(self.act_batch(np.asarray(state, dtype=float).reshape(1, 7))[0])

    def act_batch(
        self, states: np.ndarray, vertical_thrust_scale: np.ndarray | None = None
    ) -> np.ndarray:
        """Greedy actions (B,) for physical states (B, 7), shielded if the file says so (with the
        measured vertical thrust fraction (B,), if given: `pd_core.shield.shield_actions`)."""
        greedy = np.argmax(self.q_values(states), axis=-1)
        if self.shield is None:
            return greedy
        shielded, fired = shield_actions(
            greedy, states, self.actions, self.shield, vertical_thrust_scale
        )
        self.shield_fired += int(fired.sum())
        return shielded

    def thrust(self, action: int) -> np.ndarray:
        """Thrust (3,) in N of an action index; ValueError if out of range."""
        return self.actions.thrust(int(action))


def _relu(x: np.ndarray) -> np.ndarray:
    return np.maximum(x, 0.0)


def _one_line(exc: BaseException, limit: int = 160) -> str:
    """The first line of an exception's message (torch's run to many), shortened."""
    text = str(exc).strip().splitlines()
    first = text[0].strip() if text else ""
    first = first if len(first) <= limit else first[: limit - 3] + "..."
    return f"{type(exc).__name__}: {first}" if first else type(exc).__name__


def _load_weights(pt: Path) -> dict[str, Any]:
    """The tensors of a .pt file (torch.load with weights_only=True: no code runs), or
    PolicyLoadError in one line that says what the file is."""
    import torch  # optional heavy dependency: only loading a policy needs it

    try:
        state = torch.load(pt, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many types for corrupt or hostile files
        text = str(exc)
        hostile = re.search(r"Unsupported global: GLOBAL (\S+)", text)
        if hostile:
            raise PolicyLoadError(
                f"{pt}: refused: it holds Python objects ({hostile.group(1)}), not only tensors; "
                "policy files are read as plain tensors, and nothing in this one was run"
            ) from None
        detail = re.search(r"WeightsUnpickler error:\s*(.+)", text)
        why = detail.group(1).strip() if detail else _one_line(exc)
        raise PolicyLoadError(
            f"{pt}: cannot load weights: not a PyTorch tensor file ({why})"
        ) from None
    if not isinstance(state, dict) or not all(isinstance(v, torch.Tensor) for v in state.values()):
        raise PolicyLoadError(f"{pt}: cannot load weights: not a dict of tensors")
    return state


def _weights_mismatch(state: dict[str, Any], want: dict[str, Any]) -> str | None:
    """None if `state` has exactly the tensors of `want` with their shapes, else what differs."""
    missing = sorted(set(want) - set(state))
    extra = sorted(set(state) - set(want))
    if missing or extra:
        return f"tensors missing {missing[:3]}, unexpected {extra[:3]}"
    for name, t in want.items():
        if tuple(state[name].shape) != tuple(t.shape):
            return (
                f"{name} has shape {list(state[name].shape)} in the file, the network needs "
                f"{list(t.shape)}"
            )
    return None


def load_policy(path: str | Path, shield: str = "file") -> Policy:
    """Load `<name>.pt` + `<name>.json`; PolicyLoadError naming the file and what is wrong
    (one line; never advice to lower the safety of the load). `shield` (SHIELD_MODES): fly
    behind the braking shield if the metadata asks for it ("file"), always ("always": the file's
    settings or the defaults), or never ("never": the bare network)."""
    if shield not in SHIELD_MODES:
        raise ValueError(f"shield must be one of {', '.join(SHIELD_MODES)}, got {shield!r}")
    from pd_core.dqn.network import QNetwork  # imports torch: optional heavy dependency

    pt, js = paths_for(path)
    for f in (pt, js):
        if not f.is_file():
            raise PolicyLoadError(f"{f}: no such file (a policy is a .pt and a .json beside it)")
    for f in (pt, js):
        if f.stat().st_size == 0:
            raise PolicyLoadError(f"{f}: empty file (0 bytes), not a policy file")
    try:
        meta = json.loads(js.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise PolicyLoadError(f"{js}: unreadable metadata: {_one_line(exc)}") from exc
    if not isinstance(meta, dict):
        raise PolicyLoadError(f"{js}: unreadable metadata: not a JSON object")
    diffs = [
        f"{k}: file has {meta.get(k)!r}, code has {v!r}"
        for k, v in expected_metadata().items()
        if not _close(meta.get(k), v)
    ]
    if diffs:
        raise PolicyLoadError(f"{js}: metadata does not match the code: " + "; ".join(diffs))
    try:
        shape = meta["network"]
        net = QNetwork(
            int(shape["n_inputs"]),
            int(shape["n_actions"]),
            tuple(shape["hidden"]),
            shape["activation"],
            near_pad=bool(shape.get("near_pad", False)),
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise PolicyLoadError(f"{js}: bad network description: {exc}") from exc
    n_actions = int(np.prod(meta["n_per_axis"]))
    if net.n_actions != n_actions or net.n_inputs != 7:
        raise PolicyLoadError(
            f"{js}: network has {net.n_inputs} inputs / {net.n_actions} outputs, "
            f"need 7 / {n_actions}"
        )
    state = _load_weights(pt)
    why = _weights_mismatch(state, net.state_dict())
    if why is not None:
        raise PolicyLoadError(f"{pt}: cannot load weights: {why} (network described in {js})")
    net.load_state_dict(state)
    try:
        filed = ShieldParams.from_dict(meta["shield"]) if meta.get("shield") else None
    except (AttributeError, TypeError, ValueError) as exc:
        raise PolicyLoadError(f"{js}: bad shield settings: {_one_line(exc)}") from exc
    chosen = {"file": filed, "always": filed or ShieldParams(), "never": None}[shield]
    return Policy(net, meta, chosen)
