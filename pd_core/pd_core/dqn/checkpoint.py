"""Resumable checkpoints of a training run: one `checkpoint.pt` per run folder, written atomically.

Read with `torch.load(weights_only=True)`, so a checkpoint (like a policy file) cannot run code:
every non-tensor part is stored as JSON text.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np
import torch

from pd_core.runtime.policy_file import code_version, expected_metadata

CHECKPOINT = "checkpoint.pt"


def checkpoint_metadata(network_shape: dict[str, Any], seed: int) -> str:
    """What a checkpoint must agree with to resume under this code (JSON text)."""
    return json.dumps(
        {
            **expected_metadata(),
            "network": network_shape,
            "code_version": code_version(),
            "seed": seed,
        }
    )


def write_checkpoint(run_dir: Path, state: dict[str, Any]) -> Path:
    """Write `state` to run_dir/checkpoint.pt through a temporary file (never half a checkpoint)."""
    path = run_dir / CHECKPOINT
    tmp = path.with_suffix(".tmp")
    torch.save(state, tmp)
    os.replace(tmp, path)
    return path


def read_checkpoint(path: str | Path) -> tuple[Path, dict[str, Any]]:
    """(checkpoint path, state) of a run folder or checkpoint file; refuses one made under other
    constants (action space, thrust limits, scaling, dt), naming each difference."""
    p = Path(path)
    ckpt = p / CHECKPOINT if p.is_dir() else p
    if not ckpt.is_file():
        raise FileNotFoundError(f"{ckpt}: no checkpoint here")
    try:
        state = torch.load(ckpt, map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - any unreadable file is one refusal, one line
        raise ValueError(f"{ckpt}: not a readable checkpoint ({type(exc).__name__})") from None
    saved = json.loads(state.get("metadata", "{}"))
    diffs = [
        f"{k}: checkpoint has {saved.get(k)!r}, code has {v!r}"
        for k, v in expected_metadata().items()
        if k in saved and saved[k] != v
    ]
    if diffs:
        raise ValueError(f"{ckpt}: checkpoint does not match the code: " + "; ".join(diffs))
    return ckpt, state


def encode(d: dict[str, Any]) -> dict[str, Any]:
    """numpy arrays to tensors (copies), everything else to JSON text: loadable weights_only."""
    return {
        k: torch.from_numpy(v.copy()) if isinstance(v, np.ndarray) else json.dumps(v)
        for k, v in d.items()
    }


def decode(d: dict[str, Any]) -> dict[str, Any]:
    """The inverse of `encode`."""
    return {
        k: v.numpy().copy() if isinstance(v, torch.Tensor) else json.loads(v) for k, v in d.items()
    }
