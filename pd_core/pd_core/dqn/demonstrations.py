"""The demonstration memory of Sec. 2.3: open-loop OCP demonstrations from a file and closed-loop
episodes of a reference controller, as n-step transitions with the training reward (Eq. 12)."""

from __future__ import annotations

from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from pd_core.actions import DEFAULT_ACTIONS
from pd_core.config import RewardConfig
from pd_core.controllers import make_controller
from pd_core.demos import load_demos
from pd_core.dqn.config import TrainConfig
from pd_core.dqn.replay import DemoMemory, nstep_from_episodes
from pd_core.evaluate import rollout
from pd_core.reward import reward as shaped_reward
from pd_core.state import scale_state

CONTROLLER_SEED_OFFSET = 50_000_000
"""Controller demonstrations fly seeds disjoint from training (cfg.seed * 1000) and evaluation."""


class DemoTransitions(NamedTuple):
    """Scaled n-step transitions ready for `DemoMemory.fill` (same fields as `ReplaySample`)."""

    obs: np.ndarray  # (N, 7) scaled states (Eq. 20)
    actions: np.ndarray  # (N,) int64
    rewards: np.ndarray  # (N,) n-step discounted reward sums
    next_obs: np.ndarray  # (N, 7) scaled states after k <= n steps
    discounts: np.ndarray  # (N,) 0 if terminated within the n steps, else gamma^k


class PhysicalSteps(NamedTuple):
    """Consecutive 1-step transitions in SI units, grouped by `episode` (contiguous, in order)."""

    states: np.ndarray  # (N, 7)
    actions: np.ndarray  # (N,)
    next_states: np.ndarray  # (N, 7)
    dones: np.ndarray  # (N,) bool: the episode terminated at this step
    episode: np.ndarray  # (N,) episode id


def demo_transitions(
    steps: PhysicalSteps, cfg: TrainConfig, reward_cfg: RewardConfig
) -> DemoTransitions:
    """n-step transitions of physical demonstration steps, rewards recomputed with Eq. 12 so a
    demonstration is scored by the same reward as the agent's own experience."""
    thrust = DEFAULT_ACTIONS.thrust(steps.actions)
    rewards = shaped_reward(
        steps.next_states[:, 0:3], steps.next_states[:, 3:6], thrust, reward_cfg
    )
    return DemoTransitions(
        *nstep_from_episodes(
            scale_state(steps.states),
            np.asarray(steps.actions, dtype=np.int64),
            rewards,
            scale_state(steps.next_states),
            np.asarray(steps.dones, dtype=bool),
            np.asarray(steps.episode),
            cfg.gamma,
            cfg.n_step,
        )
    )


def controller_steps(name: str, n_episodes: int, seed: int) -> tuple[PhysicalSteps, float]:
    """1-step transitions of a reference controller flying the disturbed env; its success rate."""
    ro = rollout(make_controller(name), n_episodes, seed, keep_trajectories=n_episodes)
    s, a, nx, d, ep = [], [], [], [], []
    for i, (path, acts) in enumerate(zip(ro.trajectories, ro.actions, strict=True)):
        t = len(acts)
        s.append(path[:-1])
        nx.append(path[1:])
        a.append(acts)
        done = np.zeros(t, dtype=bool)
        done[-1] = bool(ro.terminated[i])
        d.append(done)
        ep.append(np.full(t, i))
    steps = PhysicalSteps(*(np.concatenate(x) for x in (s, a, nx, d, ep)))
    return steps, float(np.mean(ro.landed))


def file_steps(path: Path) -> PhysicalSteps:
    """The open-loop OCP demonstrations of a `pd-ocp demos` file (Eqs. 5-7)."""
    if not path.is_file():
        raise FileNotFoundError(
            f"demonstration file {path} not found (make it with `pd-ocp demos`, or pass "
            "--demos '' to train without the file)"
        )
    ds, _meta = load_demos(path)
    return PhysicalSteps(ds.states, ds.actions, ds.next_states, ds.dones, ds.episode)


def build_demo_memory(
    cfg: TrainConfig, reward_cfg: RewardConfig
) -> tuple[DemoMemory | None, dict[str, Any]]:
    """The demonstration memory from the demos file and/or controller episodes (None: no demos)."""
    parts: list[DemoTransitions] = []
    info: dict[str, Any] = {}
    if cfg.batch_demo > 0 and cfg.demos:
        steps = file_steps(Path(cfg.demos))
        parts.append(demo_transitions(steps, cfg, reward_cfg))
        info["file"] = {"path": str(Path(cfg.demos)), "transitions": len(steps.actions)}
    if cfg.batch_demo > 0 and cfg.controller_demo_episodes > 0:
        steps, success = controller_steps(
            cfg.controller, cfg.controller_demo_episodes, cfg.seed + CONTROLLER_SEED_OFFSET
        )
        parts.append(demo_transitions(steps, cfg, reward_cfg))
        info["controller"] = {
            "name": cfg.controller,
            "episodes": cfg.controller_demo_episodes,
            "transitions": len(steps.actions),
            "success_rate": success,
        }
    if not parts:
        return None, info
    return DemoMemory.fill(*(np.concatenate(col) for col in zip(*parts, strict=True))), info
