"""Training configuration: one dataclass, a docstring per field, turned into `pd-train` flags.

The fields are flat (their names are the flags, the presets' and sweeps' keys and config.json's)
and each belongs to one of `GROUPS`: run, network, update, replay, schedule, demonstrations,
environment and evaluation. `cfg.group("replay")` reads one group, `cfg.grouped()` nests them and
`pd-train --help` lists the flags group by group.

Presets: `paper-agent1` (Table 2, with demonstrations), `paper-agent2` (no demonstrations, k = 200),
`best` (what won our comparisons on the nominal problem), `robust` (issue 10: trained under
dispersions from ZEM/ZEV demonstrations; see models/<name>.md) and `ocp` (issue 32: from
scratch, demonstrations of the optimal-control teacher `mpc-fuel-reserve-state` only). Flags given
on the command line override the preset.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import inspect
from dataclasses import dataclass, field, fields, replace
from typing import Any

from pd_core.config import DQN_PAPER, REWARD, RewardConfig
from pd_core.deprecation import renamed
from pd_core.runtime.config import RuntimeConfig


@dataclass
class TrainConfig:
    preset: str = "paper-agent1"
    """preset the other fields start from: paper-agent1, paper-agent2, best, robust or ocp"""
    seed: int = 1
    """seed of torch, numpy and the envs: the same seed gives the same weights on CPU"""
    episodes: int = DQN_PAPER.episodes
    """training stops after this many finished episodes (summed over the batched envs)"""
    max_minutes: float = 0.0
    """training also stops after this many minutes of wall time, counted from the start of the
    run: building the demonstrations (and the recovery search) is part of it (0: no limit)"""
    max_updates: int = 0
    """training also stops after this many gradient updates (0: no limit)"""
    num_envs: int = 1
    """batched environments stepped together (the paper: 1)"""
    updates_per_step: float = 1.0
    """gradient updates per batched env step, i.e. per num_envs env transitions; fractions
    accumulate. The paper's ratio, one update per env transition, is updates_per_step = num_envs
    (e.g. --num-envs 16 --updates-per-step 16: the updates of a step run together after it)"""
    learning_starts: int = 1000
    """agent transitions stored before the first gradient update"""
    hidden: tuple[int, ...] = DQN_PAPER.hidden
    """hidden units of the Q-network (Table 2)"""
    activation: str = "tanh"
    """activation of the hidden layers: tanh (paper) or relu"""
    near_pad: bool = False
    """ours: the first layer also sees tanh(position / 2, 2, 10 m; velocity / 0.5, 0.5, 2 m/s)
    (pd_core.state.near_pad_features), which resolve the last metres; a paper network given as
    init_policy is widened with zero weights on them"""
    thrust_input: bool = False
    """ours (issue 68): the first layer also sees the vertical thrust fraction the runtime layer
    counts on (pd_core.state.thrust_input: 0 nominal, 1 at 80 %), recorded with every
    demonstration and label; needs layer and dagger_rounds (no interaction: the env's
    observations do not have it). An init_policy without it is widened with zero weights"""
    input_norm_init: bool = False
    """fold a standardisation of the scaled inputs (mean/std of visited states) into the first
    layer's initial weights; same architecture, better-conditioned start"""
    optimizer: str = "rmsprop"
    """rmsprop (paper) or adam"""
    lr: float = DQN_PAPER.learning_rate
    """learning rate (Table 2: 1e-5)"""
    lr_finetune: float = 0.0
    """learning rate once pre-training on demonstrations is over (0: keep lr)"""
    grad_clip: float = 0.0
    """clip the gradient norm to this (0: off)"""
    epsilon0: float = DQN_PAPER.epsilon0
    """initial exploration rate epsilon_0 (Table 2)"""
    epsilon_final: float = 0.0
    """exploration rate at the end of the schedule"""
    epsilon_episodes: int = DQN_PAPER.epsilon_episodes
    """finished episodes over which epsilon decays linearly (Table 2: n_eps = 4000)"""
    gamma: float = DQN_PAPER.gamma
    """discount factor (Table 2)"""
    batch_agent: int = DQN_PAPER.batch_agent
    """k: agent transitions per minibatch (Table 2; Agent 2: 200)"""
    batch_demo: int = DQN_PAPER.batch_demo
    """k_demo: demonstration transitions per minibatch (0: no demonstrations)"""
    target_period: int = DQN_PAPER.target_period_steps
    """n_T: the target network is copied every this many gradient updates (= env transitions at
    the paper's ratio, one update per transition)"""
    buffer_size: int = 1_000_000
    """capacity of the agent replay memory (FIFO); the demonstration memory is never overwritten"""
    double_dqn: bool = False
    """double DQN: the online network picks the next action, the target network values it"""
    n_step: int = 1
    """n-step returns (1: Eq. 11)"""
    loss: str = "mse"
    """mse (Eq. 11, the paper) or huber"""
    margin: float = 0.0
    """weight of DQfD's large-margin loss on demonstration transitions (0: off)"""
    margin_value: float = 0.8
    """margin l(a_E, a) for a != a_E in the large-margin loss"""
    demos: str = "data/demos_7x7x3.npz"
    """demonstration file (pd_core.demonstrations.open_loop format; empty: none)"""
    demo_memory: str = ""
    """a demonstration memory made by pd-demos for this config (pd_core.dqn.demo_file): trained
    on as it is, nothing built or flown; refused if made for another config. Empty: build it"""
    controller_demo_episodes: int = 0
    """episodes flown by the reference controller (pd_core.teachers.zemzev) added as
    demonstrations"""
    controller: str = "zemzev"
    """controller(s) flying the controller demonstrations, under `dispersions`: zemzev, the MPC
    teacher mpc-fuel / mpc-energy (flown on every core), or a comma list sharing the episodes"""
    demo_landed_only: bool = False
    """keep only the controller demonstrations of episodes that landed (a teacher that fails
    under a dispersion would otherwise be imitated into the crash by the margin loss)"""
    recovery_demo_episodes: int = 0
    """DAgger-style demonstrations: episodes of the (first) `controller` started from states that
    `init_policy` visits under `dispersions`, one drawn uniformly along each of its episodes, so
    the teacher shows how to recover from where the student goes (kept as demo_landed_only says)"""
    label_episodes: int = 0
    """DAgger labels: `init_policy` flies this many episodes under `dispersions` behind the
    runtime layer and the (first) `controller` labels, in shadow, every state it decides on
    (pd_core.demonstrations.dagger); each label is a one-step demonstration"""
    label_noise: float = 0.0
    """DAgger labels: the share of the labelled episodes' steps on which the student flies a
    uniformly random action instead of its own (noise injection, DART), so that the teacher
    also labels the recoveries from errors a greedy student seldom makes; in [0, 1)"""
    dagger_rounds: int = 0
    """DAgger rounds after pre-training (Ross et al. 2011, aggregated): each flies the current
    network on `label_episodes` new episodes, adds the teacher's labels to the demonstrations
    (none is dropped), then pre-trains `pretrain_updates` more; the run ends after the last
    round, with no interaction phase (0: none)"""
    weight_average: float = 0.0
    """Polyak averaging: after every gradient update the averaged network moves towards the
    online one, w_avg <- d w_avg + (1 - d) w, with this decay d (horizon 1 / (1 - d) updates);
    the evaluations, best.pt, final.pt and the DAgger student fly the averaged network. 0: the
    online network itself; in [0, 1)"""
    recovery_failed_share: float = 0.0
    """share of the recovery demonstrations started from episodes the student failed (searched
    for among further episodes) instead of from any episode"""
    layer: bool = False
    """the policy flies behind the runtime layer (pd_core.runtime: its braking limit and other
    rules): the periodic evaluations (hence best.pt), the recovery search and the controller
    demonstrations fly with it (the demonstrations hold the actions flown), and the saved
    policies' metadata asks for it. Training episodes fly without it: with it, the overridden
    actions' Q-values stayed untrained and the median fuel drifted from 338 to 450 kg in 13 min.
    Once called shield (--shield and a config's "shield" still work, deprecated)"""
    layer_settings: str = ""
    """with layer: runtime-layer settings changed from the code's default for the evaluations,
    the demonstrations, the DAgger student and the saved files, as pd-eval's set:K=V,K=V (e.g.
    brake_mass_loss=1,unmeasured_thrust=0.8; "": the default layer)"""
    init_policy: str = ""
    """policy file (.pt with its .json) whose weights start the Q and target networks: fine-tuning
    (its network must match hidden/activation; "": random initialisation)"""
    pretrain_updates: int = 0
    """gradient updates on demonstrations only before interaction starts (DQfD pre-training)"""
    dispersions: str = ""
    """dispersions the training envs, the controller demonstrations and the periodic evaluations
    sample (domain randomisation): a scenario or campaign name or a YAML file of
    pd_core.dispersions ("": nominal, the paper)"""
    scenario_sampling: str = "uniform"
    """how training episodes draw their `dispersions` scenario: uniform, or failures (in
    proportion to each scenario's recent training failure rate, over a uniform floor; the
    periodic evaluations stay uniform)"""
    scenario_uniform_share: float = 0.5
    """with scenario_sampling=failures: the share of episodes still drawn uniformly"""
    scenario_window: int = 200
    """with scenario_sampling=failures: recent training episodes per scenario it counts"""
    fuel_weight: float = 1.0
    """multiplies beta (control effort) of the training reward; evaluation is unaffected"""
    precision_bonus: float = 0.0
    """landing bonus on top of kappa, this * (1 - miss / 5 m), in the training reward (0: the
    paper's flat bonus); evaluation is unaffected"""
    eval_every_s: float = 60.0
    """greedy evaluation on eval_episodes seeded episodes every this many seconds (0: off)"""
    eval_every_updates: int = 0
    """> 0: evaluate every this many gradient updates (pre-training included) instead of by
    time, so which networks are evaluated, and so best.pt, does not depend on the machine"""
    eval_episodes: int = 200
    """episodes of each periodic greedy evaluation (seed eval_seed, separate from pd-eval's)"""
    eval_seed: int = 900_000
    """seed of the periodic evaluations"""
    checkpoint_every_s: float = 300.0
    """write a resumable checkpoint this often (and at the end)"""
    run_dir: str = ""
    """run folder (default runs/<preset>__<seed>__<time>)"""
    resume: str = ""
    """run folder or checkpoint.pt to resume: networks, optimiser, replay memories, schedules"""
    address: str = ""
    """Ray cluster that flies the teacher's demonstrations and DAgger labels: auto, host:port,
    ray://host:port, or local (a local Ray instance); "": a process pool on this machine"""
    torch_threads: int = 1
    """torch CPU threads (1 keeps runs repeatable and leaves the other core free)"""
    device: str = "auto"
    """where the networks train: cpu, cuda, or auto (cuda when torch sees one, else cpu). On cuda
    the replay memories live and sample on the GPU and the whole update step is one CUDA graph;
    cpu keeps numpy replay memories and resumes bit for bit"""
    progress: bool = True
    """show a tqdm progress bar"""
    loop: str = "auto"
    """the training loop: reference (pd_core.dqn.train, every option, resumable), device
    (pd_core.dqn.device_loop: Table 2's algorithm with the replay memories, the minibatch draws
    and blocks of updates_per_step updates on the device, one CUDA graph each on cuda; also runs
    on the CPU), or auto (device on cuda where the config is Table 2's algorithm, else
    reference)"""
    agents: str = ""
    """more agents trained together with this one by the device loop, as preset:seed pairs
    (e.g. paper-agent1:2,paper-agent2:1; the flags given apply to them too); each has its own run
    folder under run_dir, named <preset>__<seed>"""

    def to_dict(self) -> dict[str, Any]:
        """Flat: field -> value (config.json, checkpoints, policy files)."""
        d = dataclasses.asdict(self)
        d["hidden"] = list(self.hidden)
        return d

    def group(self, name: str) -> ConfigGroup:
        """A read-only view of the fields of one of `GROUPS`."""
        return ConfigGroup(self, name)

    def grouped(self) -> dict[str, dict[str, Any]]:
        """Nested: group -> field -> value, in the order of `GROUPS`."""
        d = self.to_dict()
        return {name: {k: d[k] for k in members} for name, members in GROUPS.items()}

    @classmethod
    def from_dict(cls, d: dict[str, Any], overrides: dict[str, Any] | None = None) -> TrainConfig:
        """The config `to_dict` wrote (a run's config.json, a checkpoint's, a policy file's
        training config), an old field name read as its new one (`current_names`), with
        `overrides` (fields by their current names) changed."""
        d = {**current_names(d), **(overrides or {})}
        return cls(**{**d, "hidden": tuple(d["hidden"])})

    @property
    def shield(self) -> bool:
        """Deprecated (it warns): the old name of `layer`."""
        renamed("TrainConfig.shield", "TrainConfig.layer")
        return self.layer

    @shield.setter
    def shield(self, value: bool) -> None:
        renamed("TrainConfig.shield", "TrainConfig.layer")
        self.layer = value


GROUPS: dict[str, tuple[str, ...]] = {
    "run": (
        "preset", "seed", "run_dir", "resume", "device", "loop", "agents", "address",
        "torch_threads", "progress", "checkpoint_every_s",
    ),
    "network": (
        "hidden", "activation", "near_pad", "thrust_input", "input_norm_init", "init_policy",
    ),
    "update": (
        "optimizer", "lr", "lr_finetune", "grad_clip", "gamma", "double_dqn", "n_step", "loss",
        "margin", "margin_value", "target_period", "weight_average",
    ),
    "replay": (
        "num_envs", "updates_per_step", "learning_starts", "buffer_size", "batch_agent",
        "batch_demo",
    ),
    "schedule": (
        "episodes", "max_minutes", "max_updates", "epsilon0", "epsilon_final",
        "epsilon_episodes", "pretrain_updates", "dagger_rounds",
    ),
    "demonstrations": (
        "demos", "demo_memory", "controller", "controller_demo_episodes", "demo_landed_only",
        "recovery_demo_episodes", "recovery_failed_share", "label_episodes", "label_noise",
    ),
    "environment": (
        "dispersions", "scenario_sampling", "scenario_uniform_share", "scenario_window",
        "fuel_weight", "precision_bonus", "layer", "layer_settings",
    ),
    "evaluation": ("eval_every_s", "eval_every_updates", "eval_episodes", "eval_seed"),
}  # fmt: skip
"""Every field of `TrainConfig` in one group: `pd-train --help` lists them so, `grouped()`
nests them so and `cfg.group(name)` reads one group. The fields themselves stay flat, so every
flag, preset, sweep FIELD=VALUE, config.json, checkpoint and policy file keeps its names."""
GROUP_TITLES = {
    "run": "run: where, how and under which seed it runs",
    "network": "network: the Q-network and its inputs",
    "update": "update: the loss and the optimiser (Eq. 11 and Table 2)",
    "replay": "replay: environments, memories and minibatches",
    "schedule": "schedule: when exploration, pre-training, DAgger rounds and the run end",
    "demonstrations": "demonstrations: the teacher's episodes and labels",
    "environment": "environment: dispersions, reward and the runtime layer",
    "evaluation": "evaluation: the periodic greedy evaluations that pick best.pt",
}


class ConfigGroup:
    """A read-only view of one group of a `TrainConfig`: `cfg.group("replay").batch_agent`;
    a field of another group is an AttributeError, so code given a group reads only it."""

    __slots__ = ("_cfg", "_name")

    def __init__(self, cfg: TrainConfig, name: str) -> None:
        if name not in GROUPS:
            raise ValueError(f"no config group {name!r}; choose from {sorted(GROUPS)}")
        object.__setattr__(self, "_cfg", cfg)
        object.__setattr__(self, "_name", name)

    def __getattr__(self, field_name: str) -> Any:
        if field_name not in GROUPS[self._name]:
            raise AttributeError(f"{field_name!r} is not in the config group {self._name!r}")
        return getattr(self._cfg, field_name)

    def __setattr__(self, field_name: str, value: Any) -> None:
        raise AttributeError(f"config group {self._name!r} is read-only")

    def to_dict(self) -> dict[str, Any]:
        d = self._cfg.to_dict()
        return {k: d[k] for k in GROUPS[self._name]}

    def __repr__(self) -> str:
        return f"ConfigGroup({self._name!r}, {self.to_dict()!r})"


def group_of(field_name: str) -> str:
    """The group a field belongs to."""
    for name, members in GROUPS.items():
        if field_name in members:
            return name
    raise KeyError(f"no TrainConfig field {field_name!r}")


RENAMED_FIELDS = {"shield": "layer"}
"""old field names kept for one release: a config dict (an old run's config.json), `preset`'s
overrides, a pd-train flag (--shield) and pd-sweep's FIELD=VALUE take them; old -> new"""


def current_names(values: dict[str, Any], flags: bool = False) -> dict[str, Any]:
    """`values` (field -> value) with an old name of RENAMED_FIELDS moved to its new one (it
    warns; `flags`: named as pd-train flags); ValueError where both are given and disagree."""
    out = dict(values)
    for old, new in RENAMED_FIELDS.items():
        if old not in out:
            continue
        value = out.pop(old)
        if flags:
            old_name, new_name = f"--{old.replace('_', '-')}", f"--{new.replace('_', '-')}"
        else:
            old_name, new_name = f"the training config field {old!r}", repr(new)
        renamed(old_name, new_name)
        if out.get(new, value) != value:
            raise ValueError(f"{old_name} and {new_name} disagree (give only {new_name})")
        out[new] = value
    return out


PRESETS: dict[str, dict[str, Any]] = {
    # Table 2, Sec. 2.3 and 3.2: one env, one update per step, the 33 OCP demonstrations.
    "paper-agent1": {},
    # Sec. 3.2: no demonstrations, k = 200.
    "paper-agent2": {"batch_agent": DQN_PAPER.batch_agent_no_demo, "batch_demo": 0, "demos": ""},
    # Ours: what won against paper-agent1 on the same evaluation (see models/*.md).
    "best": {
        "num_envs": 32,
        "updates_per_step": 1.0,
        "learning_starts": 5000,
        "episodes": 1_000_000,
        "max_minutes": 55.0,
        "optimizer": "adam",
        "lr": 1e-3,
        "lr_finetune": 1e-4,
        "grad_clip": 10.0,
        "epsilon0": 0.05,
        "epsilon_final": 0.0,
        "epsilon_episodes": 2000,
        "batch_agent": 128,
        "batch_demo": 128,
        "target_period": 1000,
        "buffer_size": 500_000,
        "double_dqn": True,
        "n_step": 3,
        "loss": "huber",
        "margin": 1.0,
        "demos": "",
        "controller_demo_episodes": 1000,
        "pretrain_updates": 60_000,
        "eval_every_s": 150.0,
        "eval_episodes": 300,
    },
}
# Ours for issue 10: the shipped `best` policy fine-tuned under domain randomisation over the whole
# `standard` campaign, with demonstrations flown under the same dispersions (the episodes that
# landed) and as many started from states the starting policy itself visits there (DAgger-style);
# periodic evaluations fly the same campaign. Each further round (`--init-policy` the previous
# round) starts its recovery episodes where that round goes; --recovery-failed-share starts a
# share of them on the student's crash paths. What each round reached: models/pd_dqn_robust.md
# and docs/experiments/.
PRESETS["robust"] = {
    **PRESETS["best"],
    "init_policy": "models/pd_dqn_best.pt",
    "dispersions": "standard",
    "controller": "zemzev",
    "controller_demo_episodes": 1000,
    "recovery_demo_episodes": 1000,
    "demo_landed_only": True,
    "pretrain_updates": 0,
    "lr": 1e-4,
    "max_minutes": 30.0,
    "eval_episodes": 500,
}

# Ours for issue 32: learns from the optimal-control teacher only, from scratch. Demonstrations
# flown by mpc-fuel-reserve-state behind the runtime layer under the `standard` dispersions
# (those that landed), DQfD pre-training on them, then interaction; no ZEM/ZEV episode, no
# starting weights.
# Budgeted and evaluated by gradient updates, not wall time, so a seed's file does not depend
# on the machine's speed or load: 201,000 updates is what 30 min gave seed 1 on the 2-core
# reference machine.
PRESETS["ocp"] = {
    **PRESETS["best"],
    "near_pad": True,
    "dispersions": "standard",
    "controller": "mpc-fuel-reserve-state",
    "controller_demo_episodes": 1500,
    "demo_landed_only": True,
    "layer": True,
    "max_minutes": 0.0,
    "max_updates": 201_000,
    "eval_every_updates": 10_000,
    "eval_episodes": 300,
}

# Ours for issue 32: DAgger after `ocp` (needs --init-policy, the `ocp` run's best.pt). Each
# round the current network flies 500 new `broad` episodes behind its layer (a random action
# on 10 % of its steps), mpc-fuel-reserve-state labels every state it decides on, the labels
# join all earlier ones (aggregated) and 20k pre-training updates follow; 500 more teacher
# episodes at the start; no interaction phase. `broad` rather than `standard` for the
# demonstrations, the rounds and the selection (docs/experiments/2026-11-28-dagger-under-broad.md).
PRESETS["ocp-dagger"] = {
    **PRESETS["ocp"],
    "dispersions": "broad",
    "controller_demo_episodes": 500,
    "label_episodes": 500,
    # the teacher also labels recoveries from the student's errors (noise injection, measured
    # in docs/experiments/2026-11-27-label-noise.md)
    "label_noise": 0.1,
    # the evaluations, the DAgger student and the files fly a Polyak average of the weights
    # (horizon 2000 updates; docs/experiments/2026-11-27-weight-average.md)
    "weight_average": 0.9995,
    "dagger_rounds": 6,
    "pretrain_updates": 20_000,
    "lr": 1e-4,
    "precision_bonus": 10.0,
    # the rounds end the run (7 x 20k updates), whatever the machine's speed
    "max_minutes": 0.0,
    "max_updates": 0,
    # its evaluations swing by 1-14 points between networks 2000 updates apart: best.pt is
    # picked from one every 2000 updates, each on 2000 episodes (docs/experiments/2026-11-26-
    # selection-every-2000-updates.md)
    "eval_every_updates": 2000,
    "eval_episodes": 2000,
}

# Ours for issue 68: `ocp-dagger` continued from its policy (--init-policy models/pd_dqn_ocp.pt),
# a network that also sees the thrust fraction its layer counts on, behind the layer that counts
# on 80 % thrust until the engine is measured; its teacher mpc-fuel-reserve-state-lf quantises
# inside that limit at that fraction; under `adapt` (`broad` with weak engines and navigation
# biases). The arm that also counts on the mass lost while braking (--controller
# mpc-fuel-reserve-state-ml --layer-settings brake_mass_loss=1,unmeasured_thrust=0.8) lands
# fewer late weak engines and combined dispersions, paired on 2000 `beyond` episodes each
# (docs/experiments/2026-12-05-adapt-student.md).
PRESETS["ocp-adapt"] = {
    **PRESETS["ocp-dagger"],
    "dispersions": "adapt",
    "controller": "mpc-fuel-reserve-state-lf",
    "thrust_input": True,
    "layer_settings": "unmeasured_thrust=0.8",
}

SCENARIO_SAMPLING = ("uniform", "failures")
DEVICES = ("auto", "cpu", "cuda")
LOOPS = ("auto", "reference", "device")
_POSITIVE = ("episodes", "num_envs", "batch_agent", "gamma", "lr", "n_step", "buffer_size")
_NON_NEGATIVE = (
    "max_minutes",
    "max_updates",
    "learning_starts",
    "lr_finetune",
    "grad_clip",
    "epsilon_final",
    "epsilon_episodes",
    "batch_demo",
    "margin",
    "controller_demo_episodes",
    "recovery_demo_episodes",
    "label_episodes",
    "label_noise",
    "dagger_rounds",
    "pretrain_updates",
    "eval_every_s",
    "eval_every_updates",
    "checkpoint_every_s",
    "torch_threads",
    "precision_bonus",
)


def check_config(cfg: TrainConfig) -> None:
    """ValueError naming the first field out of its range (before any work is done)."""
    for name in _POSITIVE:
        if not getattr(cfg, name) > 0:
            raise ValueError(f"{name} must be > 0, got {getattr(cfg, name)!r}")
    for name in _NON_NEGATIVE:
        if not getattr(cfg, name) >= 0:
            raise ValueError(f"{name} must be >= 0, got {getattr(cfg, name)!r}")
    if not 0.0 < cfg.updates_per_step:
        raise ValueError(f"updates_per_step must be > 0, got {cfg.updates_per_step!r}")
    if not (0.0 <= cfg.epsilon0 <= 1.0 and cfg.epsilon_final <= 1.0):
        raise ValueError(f"epsilon0 and epsilon_final must lie in [0, 1], got {cfg.epsilon0!r}")
    if not cfg.gamma <= 1.0:
        raise ValueError(f"gamma must be <= 1, got {cfg.gamma!r}")
    if cfg.target_period < 1 or cfg.eval_episodes < 1:
        raise ValueError("target_period and eval_episodes must be >= 1")
    if cfg.scenario_sampling not in SCENARIO_SAMPLING:
        raise ValueError(
            f"scenario_sampling must be one of {SCENARIO_SAMPLING}, got {cfg.scenario_sampling!r}"
        )
    if not 0.0 <= cfg.recovery_failed_share <= 1.0:
        raise ValueError(
            f"recovery_failed_share must lie in [0, 1], got {cfg.recovery_failed_share!r}"
        )
    if not 0.0 <= cfg.scenario_uniform_share <= 1.0 or cfg.scenario_window < 1:
        raise ValueError(
            "scenario_uniform_share must lie in [0, 1] and scenario_window be >= 1, got "
            f"{cfg.scenario_uniform_share!r}, {cfg.scenario_window!r}"
        )
    if not 0.0 <= cfg.weight_average < 1.0:
        raise ValueError(f"weight_average must lie in [0, 1), got {cfg.weight_average!r}")
    if not cfg.label_noise < 1.0:
        raise ValueError(f"label_noise must be < 1, got {cfg.label_noise!r}")
    if cfg.dagger_rounds and not (cfg.label_episodes and cfg.batch_demo and cfg.pretrain_updates):
        raise ValueError("dagger_rounds needs label_episodes, batch_demo and pretrain_updates > 0")
    if cfg.thrust_input and not (cfg.layer and cfg.dagger_rounds):
        raise ValueError("thrust_input needs layer and dagger_rounds (it is the layer's figure)")
    if cfg.thrust_input and (cfg.demos or cfg.recovery_demo_episodes):
        raise ValueError("thrust_input takes no demos file or recovery demonstrations (7 columns)")
    if cfg.layer_settings and not cfg.layer:
        raise ValueError("layer_settings needs layer (they change the runtime layer)")
    if cfg.layer_settings:
        RuntimeConfig().with_settings(cfg.layer_settings)  # an unknown setting fails here
    if cfg.device not in DEVICES:
        raise ValueError(f"device must be one of {DEVICES}, got {cfg.device!r}")
    if cfg.loop not in LOOPS:
        raise ValueError(f"loop must be one of {LOOPS}, got {cfg.loop!r}")
    for item in filter(None, (x.strip() for x in cfg.agents.split(","))):
        name, _, seed = item.partition(":")
        if name not in PRESETS or not seed.strip().lstrip("-").isdigit():
            raise ValueError(f"agents: expected preset:seed pairs, got {item!r}")
    if not cfg.hidden or min(cfg.hidden) < 1:
        raise ValueError(f"hidden must be positive layer widths, got {cfg.hidden!r}")


def preset(name: str, **overrides: Any) -> TrainConfig:
    """TrainConfig of a preset with field overrides."""
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; choose from {sorted(PRESETS)}")
    return replace(TrainConfig(), preset=name, **{**PRESETS[name], **current_names(overrides)})


def training_reward(cfg: TrainConfig) -> RewardConfig:
    """Eq. 12 with beta scaled by `fuel_weight` and the landing bonus raised by
    `precision_bonus` (1.0 and 0.0: the paper's reward)."""
    return replace(REWARD, beta=REWARD.beta * cfg.fuel_weight, precision_bonus=cfg.precision_bonus)


def field_docs() -> dict[str, str]:
    """The docstring under each field (CleanRL style), read from the source."""
    src = inspect.getsource(TrainConfig).splitlines()
    docs: dict[str, str] = {}
    names = {f.name for f in fields(TrainConfig)}
    for i, line in enumerate(src[:-1]):
        head = line.strip().split(":")[0]
        nxt = src[i + 1].strip()
        if head in names and nxt.startswith('"""'):
            text = nxt[3:]
            j = i + 1
            while not text.endswith('"""') and j + 1 < len(src):
                j += 1
                text += " " + src[j].strip()
            docs[head] = text.removesuffix('"""').strip()
    return docs


def _parse_bool(s: str) -> bool:
    v = s.lower()
    if v in ("1", "true", "yes", "on"):
        return True
    if v in ("0", "false", "no", "off"):
        return False
    raise argparse.ArgumentTypeError(f"expected a boolean, got {s!r}")


def _parse_tuple(s: str) -> tuple[int, ...]:
    v = ast.literal_eval(s) if s.strip().startswith(("(", "[")) else s.split(",")
    return tuple(int(x) for x in v)


def _flag(f: dataclasses.Field, help_: str) -> dict[str, Any]:
    """`add_argument`'s keywords for the flag of field `f`."""
    if f.name == "preset":
        return {"default": "paper-agent1", "choices": sorted(PRESETS), "help": help_}
    if f.type in ("bool", bool):
        return {"type": _parse_bool, "nargs": "?", "const": True, "help": help_}
    if f.name == "device":
        return {"choices": DEVICES, "help": help_}
    if f.name == "loop":
        return {"choices": LOOPS, "help": help_}
    if f.name == "hidden":
        return {"type": _parse_tuple, "help": help_ + "; e.g. 300,200,300"}
    return {"type": {"int": int, "float": float, "str": str}[str(f.type)], "help": help_}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """One flag per field (`--batch-agent 100`); defaults are None so presets can fill them.
    An old name of RENAMED_FIELDS is a flag too (`--shield`, deprecated)."""
    docs = field_docs()
    by_name = {f.name: f for f in fields(TrainConfig)}
    sections = {name: parser.add_argument_group(GROUP_TITLES[name]) for name in GROUPS}
    for name, members in GROUPS.items():
        for f in (by_name[m] for m in members):
            default = f.default if f.default is not dataclasses.MISSING else None
            text = docs.get(f.name, "").replace("%", "%%")  # argparse formats help with %
            help_ = f"{text} (preset default; base {default!r})"
            sections[name].add_argument("--" + f.name.replace("_", "-"), **_flag(f, help_))
    for old, new in RENAMED_FIELDS.items():
        help_ = f"deprecated: the old name of --{new.replace('_', '-')}"
        sections[group_of(new)].add_argument(
            "--" + old.replace("_", "-"), dest=old, **_flag(by_name[new], help_)
        )


def given_fields(ns: argparse.Namespace, skip: tuple[str, ...] = ("preset",)) -> dict[str, Any]:
    """The fields given as flags (not None), but those of `skip`; an old flag (--shield) gives
    its new field (`current_names`: it warns, ValueError where both disagree)."""
    names = [*(f.name for f in fields(TrainConfig)), *RENAMED_FIELDS]
    given = {name: getattr(ns, name) for name in names if getattr(ns, name, None) is not None}
    return {k: v for k, v in current_names(given, flags=True).items() if k not in skip}


def from_args(ns: argparse.Namespace) -> TrainConfig:
    return preset(ns.preset, **given_fields(ns))


__all__ = [
    "DEVICES",
    "GROUPS",
    "GROUP_TITLES",
    "ConfigGroup",
    "LOOPS",
    "PRESETS",
    "RENAMED_FIELDS",
    "TrainConfig",
    "add_arguments",
    "check_config",
    "current_names",
    "field",
    "field_docs",
    "from_args",
    "given_fields",
    "group_of",
    "preset",
    "training_reward",
]
