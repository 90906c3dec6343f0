"""Resumable checkpoints of the device loop (`pd_core.dqn.device_loop`): one `checkpoint.pt` in
the loop's folder (the agent's run folder, or the folder above several agents' run folders).

It holds every agent's config, networks and RMSProp state (the `StackedQ` tensors), its
demonstration and replay rows, counters, numpy generator, env state, observations and open
episode returns, the device generator and the updates still pending, through
`pd_core.dqn.checkpoint` (atomic, loadable `weights_only`, refused under other constants).
Resumed without `overlap` (the CPU default) a run continues bit for bit; with it (cuda), the
first step after a final checkpoint acts on the networks with the last step's updates in them.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import torch

from pd_core.dqn.checkpoint import checkpoint_metadata, decode, encode, read_checkpoint
from pd_core.dqn.config import TrainConfig

LOOP = "device"
"""the `loop` entry that tells a device-loop checkpoint from a reference-loop one"""
_COUNTERS = (
    "env_steps", "episodes", "successes", "updates", "replay_pos", "replay_size",
    "last_eval_s", "last_eval_updates", "best_eval", "epsilon",
)  # fmt: skip


def loop_state(loop: Any, pending: list[int]) -> dict[str, Any]:
    """Everything `restore` needs to continue `loop` (a `DeviceLoop`) after its last step."""
    agents = loop.agents
    memories = []
    for i, agent in enumerate(agents):
        start = i * loop.region
        demo = loop.store[start : start + agent.demo_size]
        replay = loop.store[start + loop.demo_rows : start + loop.demo_rows + agent.replay_size]
        memories += [demo.cpu().clone(), replay.cpu().clone()]
    return {
        "metadata": checkpoint_metadata(loop.q.network(0).shape_metadata(), loop.cfgs[0].seed),
        "loop": LOOP,
        "configs": json.dumps([c.to_dict() for c in loop.cfgs]),
        "run_dirs": json.dumps([str(a.run_dir) for a in agents]),
        "params": loop.q.params.cpu().clone(),
        "square_avg": loop.q.square_avg.cpu().clone(),
        "memories": memories,
        "counters": [json.dumps({k: getattr(a, k) for k in _COUNTERS}) for a in agents],
        "recent": [json.dumps(list(a.recent)) for a in agents],
        "rngs": [json.dumps(a.rng.bit_generator.state) for a in agents],
        "envs": [encode(a.env.state_dict()) for a in agents],
        "obs": [torch.from_numpy(a.obs.copy()) for a in agents],
        "ep_return": [torch.from_numpy(a.ep_return.copy()) for a in agents],
        "generator": loop.gen.get_state(),
        "pending": json.dumps(pending),
        "wall_s": json.dumps(loop._now()),
    }


def is_loop_checkpoint(path: str | Path) -> bool:
    """Whether `path` (a run folder or checkpoint file) holds a device-loop checkpoint."""
    try:
        _, state = read_checkpoint(path)
    except (OSError, ValueError):
        return False
    return state.get("loop") == LOOP


def read_loop_checkpoint(
    path: str | Path, overrides: dict[str, Any] | None = None
) -> tuple[Path, dict[str, Any], list[TrainConfig], list[Path]]:
    """(checkpoint, state, configs with `overrides`, run folders) of a device-loop checkpoint;
    ValueError for a reference-loop one."""
    ckpt, state = read_checkpoint(path)
    if state.get("loop") != LOOP:
        raise ValueError(f"{ckpt}: a reference-loop checkpoint (resume with --loop reference)")
    cfgs = [TrainConfig.from_dict(d, overrides) for d in json.loads(state["configs"])]
    return ckpt, state, cfgs, [Path(p) for p in json.loads(state["run_dirs"])]


def restore(loop: Any, state: dict[str, Any]) -> list[int]:
    """Load `state` into a `DeviceLoop` built from the same configs; returns the pending updates."""
    with torch.no_grad():
        loop.q.params.copy_(state["params"])
        loop.q.square_avg.copy_(state["square_avg"])
    for i, agent in enumerate(loop.agents):
        demo, replay = state["memories"][2 * i : 2 * i + 2]
        start = i * loop.region
        loop.store[start : start + len(demo)] = demo.to(loop.device)
        at = start + loop.demo_rows
        loop.store[at : at + len(replay)] = replay.to(loop.device)
        counters = json.loads(state["counters"][i])
        counters["best_eval"] = tuple(counters["best_eval"])
        for k, v in counters.items():
            setattr(agent, k, v)
        agent.recent.extend(tuple(x) for x in json.loads(state["recent"][i]))
        agent.rng.bit_generator.state = json.loads(state["rngs"][i])
        agent.env.load_state_dict(decode(state["envs"][i]))
        agent.obs = state["obs"][i].numpy().copy()
        agent.ep_return = state["ep_return"][i].numpy().copy()
        cfg = agent.cfg
        agent.learning = agent.episodes < cfg.episodes and not (
            0 < cfg.max_updates <= agent.updates
        )
    loop.gen.set_state(state["generator"])
    loop.wall_s = float(json.loads(state["wall_s"]))
    return [int(n) for n in json.loads(state["pending"])]
