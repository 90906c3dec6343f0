"""Demonstration memories as files with their provenance: data first, then the training loop.

`pd-demos` (or `pd-train`, which writes `demonstrations.npz` into its run folder) builds the
demonstration memory of a config (`build_demo_memory`: the demos file, the teacher-flown
episodes, recovery episodes and the first DAgger labels) and writes it with what made it: the
values of every config field the build reads (`PROVENANCE_FIELDS`), the SHA-256 of the files it
read (the open-loop demos file, the student whose states were labelled), the pd_core version and
the build's own report. `pd-train --demo-memory FILE` then trains on that memory without flying
a teacher, after checking that the file was made for this config: a field or a file that differs
is refused in one line. The memory read back is the memory built, transition for transition, so
training on it is training on a fresh build, to the bit.

`prepare_demonstrations(cfg, run_dir)` is that first step for a run: it reads `cfg.demo_memory`,
or builds the memory and writes it into the run folder, before a `Trainer` exists (`train`,
`pd-train` and the sweeps call it, then hand the result to the trainer).

DAgger rounds after the first label the network being trained, so they are built during
training (`Trainer.dagger_round_labels`), not here.
"""

from __future__ import annotations

import hashlib
import json
import time
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from pd_core import __version__
from pd_core.config import RewardConfig
from pd_core.dqn.config import TrainConfig, training_reward
from pd_core.dqn.demo_memory import build_demo_memory
from pd_core.dqn.replay import DemoMemory

FORMAT = "pd_core demonstration memory 1"
DEMO_FILE = "demonstrations.npz"
"""the memory a `pd-train` run built, in its run folder"""
COLUMNS = ("obs", "actions", "rewards", "next_obs", "discounts")
PROVENANCE_FIELDS = (
    "controller",
    "controller_demo_episodes",
    "demo_landed_only",
    "dispersions",
    "fuel_weight",
    "gamma",
    "label_episodes",
    "label_noise",
    "layer",
    "layer_settings",
    "n_step",
    "precision_bonus",
    "recovery_demo_episodes",
    "recovery_failed_share",
    "seed",
    "thrust_input",
)
"""the config fields whose values make the memory `build_demo_memory` builds (with the reward's
`fuel_weight` and `precision_bonus`); of the others it reads, `batch_demo` counts only as
whether there are demonstrations at all, `address` and `dagger_rounds` change where episodes
fly or whether a config is refused, not what the memory holds, and the two file paths are
recorded by content (`FILE_FIELDS`)"""
FILE_FIELDS = ("demos", "init_policy")


def file_sha256(path: str) -> str:
    """SHA-256 of a file ("" for no path)."""
    if not path:
        return ""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def provenance_of(cfg: TrainConfig) -> dict[str, Any]:
    """What a demonstration memory built for `cfg` depends on (JSON-ready)."""
    fields = {name: getattr(cfg, name) for name in PROVENANCE_FIELDS}
    fields["demonstrations"] = cfg.batch_demo > 0
    files = {name: file_sha256(getattr(cfg, name)) for name in FILE_FIELDS}
    return json.loads(json.dumps({"fields": fields, "files_sha256": files}))


def write_demo_file(path: Path, memory: DemoMemory, cfg: TrainConfig, info: dict) -> Path:
    """Write `memory` (made by `build_demo_memory(cfg, ...)`) and its provenance to `path`."""
    n = len(memory)
    record = {
        "format": FORMAT,
        "pd_core_version": __version__,
        **provenance_of(cfg),
        "build": info,
        "transitions": n,
    }
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp.npz")
    columns = {c: getattr(memory, c)[:n] for c in COLUMNS}
    np.savez(tmp, provenance=np.array(json.dumps(record, default=str)), **columns)
    tmp.replace(path)
    return path


def read_provenance(path: Path) -> dict[str, Any]:
    """The provenance record of a demonstration-memory file; ValueError if it is not one."""
    with np.load(path, allow_pickle=False) as z:
        if "provenance" not in z.files:
            raise ValueError(f"{path}: not a demonstration memory (make one with pd-demos)")
        record = json.loads(str(z["provenance"]))
    if record.get("format") != FORMAT:
        raise ValueError(f"{path}: format {record.get('format')!r}, this code reads {FORMAT!r}")
    return record


def read_demo_file(path: Path, cfg: TrainConfig) -> tuple[DemoMemory, dict[str, Any]]:
    """(memory, the build's report) of a file made for `cfg`; ValueError, one line, naming
    every field or file that differs from `cfg` if it was made for another config."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"demonstration memory {path} not found (make it with pd-demos)")
    record = read_provenance(path)
    want = provenance_of(cfg)
    differ = [
        f"{k}: file {record['fields'].get(k)!r}, config {v!r}"
        for k, v in want["fields"].items()
        if record["fields"].get(k) != v
    ] + [
        f"{k} (by content)"
        for k, v in want["files_sha256"].items()
        if record["files_sha256"].get(k) != v
    ]
    if differ:
        raise ValueError(f"{path} was made for another config: " + "; ".join(differ))
    with np.load(path, allow_pickle=False) as z:
        memory = DemoMemory.fill(*(z[c] for c in COLUMNS))
    return memory, {**record["build"], "memory_file": str(path)}


def demo_memory_for(
    cfg: TrainConfig, reward_cfg: RewardConfig
) -> tuple[DemoMemory | None, dict[str, Any]]:
    """The demonstration memory a run trains on: read from `cfg.demo_memory` when given, else
    built (`build_demo_memory`)."""
    if cfg.demo_memory:
        return read_demo_file(Path(cfg.demo_memory), cfg)
    return build_demo_memory(cfg, reward_cfg)


class Demonstrations(NamedTuple):
    """What a run trains on before it interacts: the memory (None: no demonstrations), the
    build's report, the file it is in and the seconds it took to read or build."""

    memory: DemoMemory | None
    info: dict[str, Any]
    path: Path | None
    seconds: float


def prepare_demonstrations(cfg: TrainConfig, run_dir: Path) -> Demonstrations:
    """Data first: the memory of `cfg.demo_memory`, or one built for `cfg` and written, with its
    provenance, to `run_dir`/`DEMO_FILE` (`pd-train --demo-memory` trains on it again)."""
    t0 = time.perf_counter()
    memory, info = demo_memory_for(cfg, training_reward(cfg))
    path: Path | None = Path(cfg.demo_memory) if cfg.demo_memory else None
    if memory is not None and path is None:
        path = write_demo_file(Path(run_dir) / DEMO_FILE, memory, cfg, info)
    return Demonstrations(memory, info, path, time.perf_counter() - t0)
