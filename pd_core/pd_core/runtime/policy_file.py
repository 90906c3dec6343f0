"""Policy files: `save_policy` writes them, `load_policy` checks them and returns a `Runtime`.

A policy is two files: `<name>.pt` (the Q-network's tensors, read with
`torch.load(weights_only=True)` so a model file cannot run code; torch is imported only here,
only to read them) and `<name>.json` (metadata: network shape, action discretisation, thrust
limits, state scaling, dt, the whole `RuntimeConfig` under "runtime", training config, seed, code
version). A file whose metadata disagrees with this code is refused with the difference named.
Files of format 1 (before the runtime config was pinned) are refused in one line that names
`python -m pd_core.runtime.migrate`, which writes their config out.
"""

from __future__ import annotations

import json
import math
import re
import subprocess
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from pd_core.actions import ActionSpace
from pd_core.config import DT_S, N_ACTIONS_PER_AXIS, RL_THRUST, STATE_SCALE, ThrustLimits
from pd_core.deprecation import renamed, renamed_argument
from pd_core.runtime.config import RuntimeConfig
from pd_core.runtime.layer import Runtime
from pd_core.runtime.network import NumpyQNetwork

FORMAT_VERSION = 2
SHIPPED_POLICY = Path("models") / "pd_dqn_adapt.pt"
"""The policy flown when none is named (pd_policy_node, pd_demo, benches), relative to the
repository root: the optimal-control student that sees its layer's thrust fraction, trained
from optimal-control teachers alone by `scripts/train_recipe.sh --adapt --seed 1`
(models/pd_dqn_adapt.md; its stage 2 is models/pd_dqn_ocp.pt)."""
LAYER_MODES = ("file", "always", "never")
"""`load_policy(layer=...)`: the runtime config the file pins; the code's default runtime
config (`RuntimeConfig()`); or none (`RuntimeConfig.off()`: the bare network)"""
RENAMED = {"SHIELD_MODES": "LAYER_MODES"}
"""old module names kept for one release (`__getattr__`): old -> new"""


class PolicyLoadError(ValueError):
    """A policy file is missing, unreadable or does not match the code."""


def check_layer_mode(layer: str) -> None:
    """ValueError in one line unless `layer` is one of `LAYER_MODES`."""
    if layer not in LAYER_MODES:
        raise ValueError(f"layer must be one of {', '.join(LAYER_MODES)}, got {layer!r}")


def __getattr__(name: str) -> Any:
    """An old name of `RENAMED` (deprecated: it warns) is its new one."""
    if name in RENAMED:
        renamed(f"{__name__}.{name}", f"{__name__}.{RENAMED[name]}")
        return globals()[RENAMED[name]]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


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
    path: str | Path,
    network: Any,
    runtime: RuntimeConfig,
    extra_metadata: dict[str, Any] | None = None,
) -> Path:
    """Write `network` (a QNetwork), the runtime config it flies behind and its metadata;
    returns the .pt path."""
    import torch

    pt, js = paths_for(path)
    pt.parent.mkdir(parents=True, exist_ok=True)
    meta = {
        **expected_metadata(),
        "network": network.shape_metadata(),
        "runtime": runtime.to_dict(),
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
        with warnings.catch_warnings():
            # A plain pickle makes torch warn (UserWarning, "Detected pickle protocol 4") before
            # it refuses the file: the refusal below says it all, in one line.
            warnings.simplefilter("ignore", UserWarning)
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


def _weights_mismatch(state: dict[str, Any], want: dict[str, tuple[int, ...]]) -> str | None:
    """None if `state` has exactly the tensors of `want` with their shapes, else what differs."""
    missing = sorted(set(want) - set(state))
    extra = sorted(set(state) - set(want))
    if missing or extra:
        return f"tensors missing {missing[:3]}, unexpected {extra[:3]}"
    for name, shape in want.items():
        if tuple(state[name].shape) != shape:
            return (
                f"{name} has shape {list(state[name].shape)} in the file, the network needs "
                f"{list(shape)}"
            )
    return None


def _network_shapes(shape: dict[str, Any]) -> dict[str, tuple[int, ...]]:
    """The tensor shapes of `pd_core.dqn.network.QNetwork` with this shape metadata."""
    width = int(shape["n_inputs"]) + (6 if shape.get("near_pad") else 0)
    width += 1 if shape.get("thrust_input") else 0
    out: dict[str, tuple[int, ...]] = {}
    sizes = [*(int(h) for h in shape["hidden"]), int(shape["n_actions"])]
    for i, h in enumerate(sizes):
        out[f"net.{2 * i}.weight"] = (h, width)
        out[f"net.{2 * i}.bias"] = (h,)
        width = h
    if shape["activation"] not in ("tanh", "relu"):
        raise ValueError(f"activation must be tanh or relu, got {shape['activation']!r}")
    return out


def read_policy(path: str | Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """(metadata, tensors by name) of a policy file, checked against this code; PolicyLoadError
    naming the file and what is wrong (one line; never advice to lower the safety of the
    load)."""
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
    if meta.get("format_version") == 1:
        raise PolicyLoadError(
            f"{js}: format 1 does not pin its runtime config; write it out with "
            f"`python -m pd_core.runtime.migrate {js}`"
        )
    diffs = [
        f"{k}: file has {meta.get(k)!r}, code has {v!r}"
        for k, v in expected_metadata().items()
        if not _close(meta.get(k), v)
    ]
    if diffs:
        raise PolicyLoadError(f"{js}: metadata does not match the code: " + "; ".join(diffs))
    try:
        shape = meta["network"]
        want = _network_shapes(shape)
    except (KeyError, TypeError, ValueError) as exc:
        raise PolicyLoadError(f"{js}: bad network description: {_one_line(exc)}") from exc
    n_actions = int(np.prod(meta["n_per_axis"]))
    if int(shape["n_actions"]) != n_actions or int(shape["n_inputs"]) != 7:
        raise PolicyLoadError(
            f"{js}: network has {shape['n_inputs']} inputs / {shape['n_actions']} outputs, "
            f"need 7 / {n_actions}"
        )
    state = _load_weights(pt)
    why = _weights_mismatch(state, want)
    if why is not None:
        raise PolicyLoadError(f"{pt}: cannot load weights: {why} (network described in {js})")
    return meta, state


def load_policy(path: str | Path, layer: str = "file", *, shield: str | None = None) -> Runtime:
    """The `Runtime` that flies the policy file at `path` (`.pt`, `.json` or no suffix):
    the network behind the runtime layer the file pins (`layer="file"`), behind the code's
    default config ("always"), or alone ("never"). PolicyLoadError in one line if the file is
    missing, unreadable, hostile or does not match the code. `shield`: the old name of `layer`
    (deprecated: it warns)."""
    layer = renamed_argument("load_policy", "shield", shield, "layer", layer, "file")
    check_layer_mode(layer)
    meta, state = read_policy(path)
    js = paths_for(path)[1]
    try:
        filed = RuntimeConfig.from_dict(meta.get("runtime"))
    except (AttributeError, TypeError, ValueError) as exc:
        raise PolicyLoadError(f"{js}: bad runtime config: {_one_line(exc)}") from exc
    dtype = filed.network_dtype
    config = {"file": filed, "always": RuntimeConfig(network_dtype=dtype)}.get(
        layer, RuntimeConfig.off(dtype)
    )
    shape = meta["network"]
    network = NumpyQNetwork(
        {k: v.detach().cpu().numpy() for k, v in state.items()},
        np.asarray(meta["state_scale"], dtype=float),
        shape["activation"],
        near_pad=bool(shape.get("near_pad", False)),
        dtype=config.network_dtype,
        thrust_input=bool(shape.get("thrust_input", False)),
    )
    space = ActionSpace(
        tuple(meta["n_per_axis"]),
        ThrustLimits(tuple(meta["thrust_min_n"]), tuple(meta["thrust_max_n"])),
    )
    return Runtime(network, config, space, name=Path(js).stem, metadata=meta)
