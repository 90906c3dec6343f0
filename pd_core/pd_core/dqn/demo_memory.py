"""The demonstration memory of Sec. 2.3: open-loop OCP demonstrations from a file and closed-loop
episodes of a reference controller, as n-step transitions with the training reward (Eq. 12)."""

from __future__ import annotations

from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from pd_core.actions import DEFAULT_ACTIONS
from pd_core.config import RewardConfig
from pd_core.demonstrations.dagger import label_transitions, student_labels
from pd_core.demonstrations.open_loop import load_demos
from pd_core.demonstrations.teacher_flown import controller_demonstrations
from pd_core.dqn.config import TrainConfig
from pd_core.dqn.replay import DemoMemory, nstep_from_episodes
from pd_core.episodes import rollout
from pd_core.reward import reward as shaped_reward
from pd_core.runtime.policy_file import load_policy
from pd_core.state import scale_inputs

CONTROLLER_SEED_OFFSET = 50_000_000
"""Controller demonstrations fly seeds disjoint from training (cfg.seed * 1000) and evaluation."""
RECOVERY_SEED_OFFSET = 60_000_000
"""... and the student episodes whose states start the recovery demonstrations, disjoint again."""
LABEL_SEED_OFFSET = 70_000_000
"""... and the student episodes the teacher labels (DAgger), disjoint again."""
FAILURE_SEARCH_FACTOR = 50
"""The student flies at most this many times the recovery episodes looking for its failures."""
FAILURE_SEARCH_CHUNK = 2000
"""... in batches of this many episodes (only the failed ones' trajectories are kept)."""


class DemoTransitions(NamedTuple):
    """Scaled n-step transitions ready for `DemoMemory.fill` (same fields as `ReplaySample`)."""

    obs: np.ndarray  # (N, 7) scaled states (Eq. 20); (N, 8) with the thrust input
    actions: np.ndarray  # (N,) int64
    rewards: np.ndarray  # (N,) n-step discounted reward sums
    next_obs: np.ndarray  # (N, 7) scaled states after k <= n steps
    discounts: np.ndarray  # (N,) 0 if terminated within the n steps, else gamma^k


class PhysicalSteps(NamedTuple):
    """Consecutive 1-step transitions in SI units, grouped by `episode` (contiguous, in order);
    with the thrust input the states carry the fraction the layer counted on as an 8th column."""

    states: np.ndarray  # (N, 7) or (N, 8)
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
            scale_inputs(steps.states),
            np.asarray(steps.actions, dtype=np.int64),
            rewards,
            scale_inputs(steps.next_states),
            np.asarray(steps.dones, dtype=bool),
            np.asarray(steps.episode),
            cfg.gamma,
            cfg.n_step,
        )
    )


def controller_steps(
    name: str,
    n_episodes: int,
    seed: int,
    dispersions: str = "",
    landed_only: bool = False,
    initial_states: np.ndarray | None = None,
    episode_seeds: np.ndarray | None = None,
    behind_layer: bool = False,
    address: str = "",
    layer_settings: str = "",
    thrust_input: bool = False,
) -> tuple[PhysicalSteps, float]:
    """1-step transitions of a reference controller (or the MPC teacher) flying the disturbed
    env under `dispersions` (from Table 3 or from `initial_states`), of every episode or only of
    those that landed; its success rate. The MPC teacher flies on every core. `behind_layer`:
    the controller flies behind the runtime layer (a student trained with `layer` flies so).
    `address`: the episodes fly as Ray tasks there instead (any controller). `layer_settings`
    change that layer; `thrust_input`: the states carry the thrust fraction it counted on (the
    next state the next step's, or the same at an episode's end)."""
    workers = None if name.startswith("mpc") else 1
    d = controller_demonstrations(
        name,
        n_episodes,
        seed,
        dispersions=dispersions,
        initial_states=initial_states,
        workers=workers,
        episode_seeds=episode_seeds,
        behind_layer=behind_layer,
        address=address,
        layer_settings=layer_settings,
    )
    if thrust_input:
        f = d.get("fraction", np.ones(len(d["episode"])))
        ep = d["episode"]
        nxt = np.append(f[1:], f[-1:])
        last = np.append(ep[1:] != ep[:-1], True)
        nxt[last] = f[last]
        d["states"] = np.hstack([d["states"], f[:, None]])
        d["next_states"] = np.hstack([d["next_states"], nxt[:, None]])
    keep = d["landed"][d["episode"]] if landed_only else np.ones(len(d["episode"]), dtype=bool)
    steps = PhysicalSteps(
        *(d[k][keep] for k in ("states", "actions", "next_states", "dones", "episode"))
    )
    return steps, float(d["success_rate"])


def recovery_starts(
    policy_path: str,
    n_episodes: int,
    seed: int,
    dispersions: str = "",
    failed_share: float = 0.0,
    behind_layer: bool = False,
) -> tuple[np.ndarray, np.ndarray, float]:
    """States (n_episodes, 7) the student policy visits, the env seed of the episode each came
    from, and the student's success rate. The student flies episodes seed.. under `dispersions`
    and one true state is drawn uniformly along each episode before touchdown. A `failed_share`
    of the states comes from episodes it did not land instead (searched for among the episodes
    that follow, up to FAILURE_SEARCH_FACTOR x n_episodes; several states per failed episode
    when it fails less often than that): the teacher then shows the way out of the student's
    own crashes, which uniform draws rarely visit once the student lands 99 %. `behind_layer`:
    the student flies behind the code's default runtime layer (pd_core.runtime.rules) even if
    its file has none."""
    student = load_policy(policy_path, layer="always" if behind_layer else "file")
    n_failed = round(failed_share * n_episodes)
    n_uniform = n_episodes - n_failed
    rng = np.random.default_rng(seed)
    starts: list[np.ndarray] = []
    seeds = list(range(seed, seed + n_uniform))
    landed: list[np.ndarray] = []
    if n_uniform:
        ro = rollout(student, n_uniform, seed, keep_trajectories=n_uniform, dispersions=dispersions)
        starts += [p[rng.integers(0, len(p) - 1)] for p in ro.trajectories]
        landed.append(ro.landed)
    failed: list[tuple[int, np.ndarray]] = []  # (env seed, trajectory)
    first = seed + n_uniform
    while n_failed and len(failed) < n_failed and first - seed < FAILURE_SEARCH_FACTOR * n_episodes:
        ro = rollout(
            student, FAILURE_SEARCH_CHUNK, first, dispersions=dispersions,
            keep_trajectories=FAILURE_SEARCH_CHUNK,
        )  # fmt: skip
        failed += [(first + i, ro.trajectories[i]) for i in np.flatnonzero(~ro.landed)]
        landed.append(ro.landed)
        first += FAILURE_SEARCH_CHUNK
    if n_failed and not failed:
        raise ValueError(f"{policy_path} failed no episode of {first - seed} under {dispersions!r}")
    for j in range(n_failed):
        s, path = failed[j % len(failed)]
        starts.append(path[rng.integers(0, len(path) - 1)])
        seeds.append(s)
    return np.stack(starts), np.array(seeds), float(np.mean(np.concatenate(landed)))


def recovery_steps(
    policy_path: str,
    name: str,
    n_episodes: int,
    seed: int,
    dispersions: str = "",
    landed_only: bool = False,
    failed_share: float = 0.0,
    behind_layer: bool = False,
    address: str = "",
) -> tuple[PhysicalSteps, float, float]:
    """Teacher `name` flying on from states the student visits (DAgger-style demonstrations:
    the student's states, the teacher's actions, and the teacher's own transitions so the TD
    loss has them too), each in the episode (env seed: scenario, draws, gusts) the state came
    from: the steps, the teacher's success rate from those states and the student's."""
    starts, seeds, student = recovery_starts(
        policy_path, n_episodes, seed, dispersions, failed_share, behind_layer
    )
    steps, teacher = controller_steps(
        name, n_episodes, seed, dispersions, landed_only, starts, seeds, behind_layer, address
    )
    return steps, teacher, student


def file_steps(path: Path) -> PhysicalSteps:
    """The open-loop OCP demonstrations of a `pd-ocp demos` file (Eqs. 5-7)."""
    if not path.is_file():
        raise FileNotFoundError(
            f"demonstration file {path} not found (make it with `pd-ocp demos`, or pass "
            "--demos '' to train without the file)"
        )
    ds, _meta = load_demos(path)
    return PhysicalSteps(ds.states, ds.actions, ds.next_states, ds.dones, ds.episode)


def label_part(
    cfg: TrainConfig, reward_cfg: RewardConfig, policy_path: str, round_index: int
) -> tuple[DemoTransitions, dict[str, Any]]:
    """DAgger round `round_index`: the (first) `controller` labels every state the policy at
    `policy_path` decides on over `label_episodes` episodes under `dispersions` (env seeds
    seed + LABEL_SEED_OFFSET + round_index * label_episodes + i, new episodes each round), as
    one-step demonstrations; and what the round saw."""
    teacher = cfg.controller.split(",")[0].strip()
    d = student_labels(
        policy_path,
        teacher,
        cfg.label_episodes,
        cfg.seed + LABEL_SEED_OFFSET + round_index * cfg.label_episodes,
        cfg.dispersions,
        address=cfg.address,
        noise=cfg.label_noise,
        layer_settings=cfg.layer_settings,
    )
    fraction = d["fraction"] if cfg.thrust_input else None
    steps = PhysicalSteps(**label_transitions(d["states"], d["labels"], fraction))
    return demo_transitions(steps, cfg, reward_cfg), {
        "round": round_index,
        "teacher": teacher,
        "student": policy_path,
        "episodes": cfg.label_episodes,
        "labels": len(d["labels"]),
        "agreement": float(np.mean(d["labels"] == d["proposed"])),
        "student_success_rate": float(np.mean(d["landed"])),
        "dispersions": cfg.dispersions or "nominal",
        "noise": cfg.label_noise,
    }


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
    names = [n.strip() for n in cfg.controller.split(",") if n.strip()]
    if cfg.batch_demo > 0 and cfg.controller_demo_episodes > 0 and names:
        info["controller"] = []
        for k, name in enumerate(names):  # the episodes are split evenly between the teachers
            n = cfg.controller_demo_episodes // len(names) + (
                k < cfg.controller_demo_episodes % len(names)
            )
            seed = cfg.seed + CONTROLLER_SEED_OFFSET + k * 1_000_000
            steps, success = controller_steps(
                name,
                n,
                seed,
                cfg.dispersions,
                cfg.demo_landed_only,
                behind_layer=cfg.layer,
                address=cfg.address,
                layer_settings=cfg.layer_settings,
                thrust_input=cfg.thrust_input,
            )
            parts.append(demo_transitions(steps, cfg, reward_cfg))
            info["controller"].append(
                {
                    "name": name,
                    "episodes": n,
                    "transitions": len(steps.actions),
                    "success_rate": success,
                    "landed_only": cfg.demo_landed_only,
                    "dispersions": cfg.dispersions or "nominal",
                    "behind_layer": cfg.layer,
                }
            )
    if cfg.batch_demo > 0 and cfg.recovery_demo_episodes > 0 and names:
        if not cfg.init_policy:
            raise ValueError("recovery_demo_episodes needs init_policy (the student whose states)")
        seed = cfg.seed + RECOVERY_SEED_OFFSET
        steps, success, student = recovery_steps(
            cfg.init_policy,
            names[0],
            cfg.recovery_demo_episodes,
            seed,
            cfg.dispersions,
            cfg.demo_landed_only,
            cfg.recovery_failed_share,
            cfg.layer,
            cfg.address,
        )
        parts.append(demo_transitions(steps, cfg, reward_cfg))
        info["recovery"] = {
            "name": names[0],
            "student": cfg.init_policy,
            "episodes": cfg.recovery_demo_episodes,
            "transitions": len(steps.actions),
            "success_rate": success,
            "student_success_rate": student,
            "failed_share": cfg.recovery_failed_share,
            "landed_only": cfg.demo_landed_only,
        }
    if cfg.batch_demo > 0 and cfg.label_episodes > 0 and names:
        if cfg.init_policy:
            part, info["labels"] = label_part(cfg, reward_cfg, cfg.init_policy, 0)
            parts.append(part)
        elif cfg.dagger_rounds == 0:
            raise ValueError("label_episodes needs init_policy (the student whose states)")
    if not parts:
        return None, info
    return DemoMemory.fill(*(np.concatenate(col) for col in zip(*parts, strict=True))), info
