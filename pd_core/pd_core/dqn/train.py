"""The training loop of `pd-train`: batched envs, two replay memories, periodic evaluation, resume.

A run folder `runs/<preset>__<seed>__<time>/` holds config.json, the CSV logs of
`pd_core.dqn.run_log`, curves.png, checkpoint.pt (resumable, `pd_core.dqn.checkpoint`), and the
policies best.pt/.json (best periodic evaluation) and final.pt/.json.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import time
from collections import deque
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from pd_core.config import STATE_SCALE
from pd_core.dqn.actor import TorchGreedy, network_kwargs
from pd_core.dqn.agent import DQNAgent, concat_samples
from pd_core.dqn.checkpoint import (
    checkpoint_metadata,
    decode,
    encode,
    read_checkpoint,
    write_checkpoint,
)
from pd_core.dqn.config import TrainConfig, check_config, training_reward
from pd_core.dqn.demo_file import Demonstrations, prepare_demonstrations
from pd_core.dqn.demo_memory import label_part
from pd_core.dqn.device import DeviceReplay, DeviceUpdate, describe_device, resolve_device
from pd_core.dqn.loop import Callback, CurvesPlot, EvalReport, ProgressBar, RunFiles, TrainingLoop
from pd_core.dqn.minibatch import DEMO, REPLAY, plan_of
from pd_core.dqn.network import QNetwork
from pd_core.dqn.replay import DemoMemory, NStepCollector, ReplayMemory, ReplaySample
from pd_core.dqn.run_log import run_folder
from pd_core.dqn.scenario_outcomes import ScenarioOutcomes
from pd_core.episodes import rollout, summarise
from pd_core.runtime.config import RuntimeConfig
from pd_core.runtime.layer import Runtime
from pd_core.runtime.policy_file import read_policy, save_policy
from pd_core.state import scale_state
from pd_core.teachers.registry import make_controller
from pd_core.vector_env import make_vector_env

EvalCallback = Callable[[dict[str, float]], None]
REPLAY_PATHS = ("host", "device", "device-numpy")
"""where the replay memories live and draw minibatches (`Trainer`'s `replay`)"""


def policy_metadata(cfg: TrainConfig, extra: dict[str, Any] | None = None) -> dict[str, Any]:
    return {
        "training": {
            "config": cfg.to_dict(),
            "seed": cfg.seed,
            "state_scale": STATE_SCALE.tolist(),
            **(extra or {}),
        }
    }


def runtime_config_for(cfg: TrainConfig) -> RuntimeConfig:
    """What a network trained with `cfg` flies behind: the default runtime layer with
    `cfg.layer_settings` changed (`RuntimeConfig.with_settings`), or none."""
    if not cfg.layer:
        return RuntimeConfig.off()
    layer = RuntimeConfig()
    return layer.with_settings(cfg.layer_settings) if cfg.layer_settings else layer


def greedy_evaluation(
    net: QNetwork, cfg: TrainConfig, episodes: int | None = None, seed: int | None = None
) -> dict[str, float]:
    """The periodic greedy evaluation of a training run: `net` (on the CPU) behind its
    runtime config on `cfg.eval_episodes` episodes of seed `cfg.eval_seed` (or those given),
    under `cfg.dispersions`; the figures of evals.csv."""
    ro = rollout(
        Runtime(TorchGreedy(net), runtime_config_for(cfg)),
        episodes or cfg.eval_episodes,
        cfg.eval_seed if seed is None else seed,
        dispersions=cfg.dispersions,
    )
    s = summarise(ro)
    t = s["table7"]
    return {
        "success_rate": s["success_rate"],
        "soft_landing_rate": s["soft_landing_rate"],
        "fuel_median": t["fuel_kg"]["median"],
        "pos_median": t["norm_ij_position_m"]["median"],
        "kvel_min": t["k_velocity_mps"]["min"],
        "mean_return": s["mean_return"],
    }


@dataclasses.dataclass
class Counters:
    env_steps: int = 0
    episodes: int = 0
    successes: int = 0
    wall_s: float = 0.0  # summed over resumed segments
    update_credit: float = 0.0
    last_eval_s: float = 0.0
    last_eval_updates: int = -1  # gradient updates at the last periodic evaluation (-1: none)
    last_ckpt_s: float = 0.0
    best_eval: tuple[float, float] = (-1.0, 0.0)  # (success rate, -median fuel)


class Trainer:
    """Holds everything a run needs; `run()` trains until a stop criterion.

    `run(callbacks)` trains through `pd_core.dqn.loop.TrainingLoop`, which reports to the run
    folder's logs, the progress bar (unless `quiet`) and curves.png, then to `callbacks`;
    `on_eval` is called with every periodic evaluation (plus wall_s, updates, episodes): how a
    sweep reports to Ray Tune. `restore` (a checkpoint's state) continues a run exactly; use
    `Trainer.resume`.

    `replay` says where the replay memories live and draw minibatches: `host` (numpy memories and
    the run's numpy generator: the CPU path, bit-for-bit resumable), `device` (torch tensors on
    `cfg.device`, indices from a torch generator there, the step a CUDA graph on cuda:
    `pd_core.dqn.device`) or `device-numpy` (the device code with the host path's index draws,
    which reproduces a `host` run on the CPU: for tests). Default: device on cuda, else host.
    """

    def __init__(
        self,
        cfg: TrainConfig,
        run_dir: Path | None = None,
        quiet: bool = False,
        on_eval: EvalCallback | None = None,
        restore: dict[str, Any] | None = None,
        replay: str | None = None,
        demos: Demonstrations | None = None,
    ) -> None:
        check_config(cfg)
        t_start = time.perf_counter()  # max_minutes counts the set-up and the demonstrations
        self.cfg = cfg
        self.quiet = quiet
        self.on_eval = on_eval
        self.device = resolve_device(cfg.device)
        self.replay_path = replay or ("device" if self.device.type == "cuda" else "host")
        if self.replay_path not in REPLAY_PATHS:
            raise ValueError(f"replay must be one of {REPLAY_PATHS}, got {self.replay_path!r}")
        on_device = self.replay_path != "host"
        self.cuda_graph = on_device and self.device.type == "cuda"
        torch.set_num_threads(max(cfg.torch_threads, 1))
        torch.manual_seed(cfg.seed)
        self.rng = np.random.default_rng(cfg.seed)
        self.reward_cfg = training_reward(cfg)
        self.agent = DQNAgent(cfg, device=self.device, capturable=self.cuda_graph)
        self.replay: ReplayMemory | DeviceReplay = (
            DeviceReplay(cfg.buffer_size, device=self.device)
            if on_device
            else ReplayMemory(cfg.buffer_size)
        )
        self.replay_gen: torch.Generator | None = None
        if self.replay_path == "device":
            self.replay_gen = torch.Generator(device=self.device)
            self.replay_gen.manual_seed(cfg.seed)
        self._device_update: DeviceUpdate | None = None
        self._q_cpu: Any = None
        self.run_dir = run_dir or run_folder(cfg)
        self.run_dir.mkdir(parents=True, exist_ok=True)
        self.demo: DemoMemory | None = None
        self.demo_info: dict[str, Any] = {}
        if restore is None and demos is not None:  # data first: built before the trainer
            t_start -= demos.seconds  # max_minutes counts their build too
        elif restore is None:  # no demonstrations given: read or built here
            demos = prepare_demonstrations(cfg, self.run_dir)
        if demos is not None:
            self.demo, self.demo_info = demos.memory, demos.info
        if cfg.init_policy and restore is None:
            self._init_from_policy(cfg.init_policy)
        if cfg.input_norm_init and restore is None:
            self.agent.init_input_normalisation(self._normalisation_states())
        self.env = make_vector_env(
            cfg.num_envs, reward_cfg=self.reward_cfg, dispersions=cfg.dispersions
        )
        self.outcomes: ScenarioOutcomes | None = None
        if cfg.scenario_sampling == "failures" and len(self.env.scenarios) > 1:
            self.outcomes = ScenarioOutcomes(
                len(self.env.scenarios), cfg.scenario_window, cfg.scenario_uniform_share
            )
            self.env.set_scenario_probs(self.outcomes.probs())
        self.obs, _ = self.env.reset(seed=cfg.seed * 1000)
        self.collector = NStepCollector(cfg.num_envs, cfg.n_step, cfg.gamma)
        self.ep_return = np.zeros(cfg.num_envs)
        self.c = Counters()
        self.recent: deque[tuple[float, int]] = deque(maxlen=100)  # (return, landed)
        self.last_info: dict[str, float] = {}
        self.pretrained = 0
        self.dagger_round = 0  # DAgger rounds labelled so far (`cfg.dagger_rounds`)
        # the set-up counts towards max_minutes: `run` restarts the clock from wall_s (a resumed
        # run's wall_s comes from its checkpoint instead)
        self.c.wall_s = time.perf_counter() - t_start
        if restore is not None:
            self.load_state_dict(restore)

    @classmethod
    def resume(
        cls,
        path: str | Path,
        overrides: dict[str, Any] | None = None,
        on_eval: EvalCallback | None = None,
        replay: str | None = None,
    ) -> Trainer:
        """Continue the run of a run folder or checkpoint file; `overrides` change config fields
        (e.g. a later `max_minutes`, or `device`: a checkpoint loads on any device, and exactly
        on the path that wrote it)."""
        ckpt, state = read_checkpoint(path)
        cfg = TrainConfig.from_dict(json.loads(state["config"]), overrides)
        return cls(cfg, run_dir=ckpt.parent, on_eval=on_eval, restore=state, replay=replay)

    def _init_from_policy(self, path: str) -> None:
        """Start both networks from a shipped policy (fine-tuning; a paper network is widened
        with near-pad inputs if the config asks for them); ValueError if it differs."""
        meta, tensors = read_policy(path)
        net = QNetwork(**network_kwargs(meta["network"]))
        net.load_state_dict(tensors)
        try:
            self.agent.q.widened_from(net)
        except ValueError:
            raise ValueError(
                f"init_policy {path}: network {net.shape_metadata()} differs from the config's "
                f"{self.agent.q.shape_metadata()}"
            ) from None
        self.agent.sync_target()
        self.agent.reset_average()

    def _normalisation_states(self) -> np.ndarray:
        """Scaled states to standardise the inputs with: the demonstrations', or else the
        states the reference controller visits (statistics only, not stored as transitions)."""
        if self.demo is not None and len(self.demo) > 0:
            return self.demo.obs[: len(self.demo)]
        ro = rollout(
            make_controller(self.cfg.controller.split(",")[0].strip()),
            50,
            self.cfg.seed + 60_000_000,
            keep_trajectories=50,
        )
        return scale_state(np.concatenate(ro.trajectories))

    def run(self, callbacks: Sequence[Callback] = ()) -> dict[str, Any]:
        """Train until a stop criterion (`TrainingLoop`); the run's summary."""
        reporters: list[Callback] = [RunFiles(), ProgressBar(self.quiet), CurvesPlot()]
        if self.on_eval is not None:
            reporters.append(EvalReport(self.on_eval))
        return TrainingLoop(self, [*reporters, *callbacks]).run()

    def pretrain_total(self) -> int:
        """Pre-training updates of the run: `pretrain_updates` before each DAgger round and
        after the last one."""
        return self.cfg.pretrain_updates * (1 + self.cfg.dagger_rounds)

    def updates_done(self) -> bool:
        """`max_updates` gradient updates are done."""
        return 0 < self.cfg.max_updates <= self.agent.updates

    def finetune_lr(self) -> None:
        """Pre-training is over: the optimiser goes on at `lr_finetune`."""
        for group in self.agent.opt.param_groups:
            group["lr"] = self.cfg.lr_finetune
        if self._device_update is not None:
            self._device_update.reset()  # a captured step keeps the lr it was captured with

    # ---- checkpoints
    def state_dict(self) -> dict[str, Any]:
        """Everything `run` needs to continue bit for bit (loadable with weights_only)."""
        return {
            "metadata": checkpoint_metadata(self.agent.q.shape_metadata(), self.cfg.seed),
            "config": json.dumps(self.cfg.to_dict()),
            "agent": self.agent.state_dict(),
            "replay": self.replay.state_dict(),
            "demo": self.demo.state_dict() if self.demo is not None else None,
            "demo_info": json.dumps(self.demo_info),
            "counters": json.dumps(dataclasses.asdict(self.c)),
            "pretrained": self.pretrained,
            "dagger_round": self.dagger_round,
            "rng": json.dumps(self.rng.bit_generator.state),
            "torch_rng": torch.get_rng_state(),
            "replay_rng": self.replay_gen.get_state() if self.replay_gen is not None else None,
            "env": encode(self.env.state_dict()),
            "obs": torch.from_numpy(self.obs.copy()),
            "ep_return": torch.from_numpy(self.ep_return.copy()),
            "collector": encode({k: getattr(self.collector, k) for k in NStepCollector.STATE}),
            "recent": json.dumps(list(self.recent)),
            "scenario_outcomes": self.outcomes.to_json() if self.outcomes else "",
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.agent.load_state_dict(state["agent"])
        self.replay.load_state_dict(state["replay"])
        if state["demo"] is not None:
            self.demo = DemoMemory(1)
            self.demo.load_state_dict(state["demo"])
        self.demo_info = json.loads(state["demo_info"])
        c = json.loads(state["counters"])
        c["best_eval"] = tuple(c["best_eval"])
        self.c = Counters(**c)
        self.pretrained = int(state["pretrained"])
        self.dagger_round = int(state.get("dagger_round", 0))
        self.rng.bit_generator.state = json.loads(state["rng"])
        torch.set_rng_state(state["torch_rng"])
        if self.replay_gen is not None and state.get("replay_rng") is not None:
            self.replay_gen.set_state(state["replay_rng"])
        self.env.load_state_dict(decode(state["env"]))
        self.obs = state["obs"].numpy().copy()
        self.ep_return = state["ep_return"].numpy().copy()
        for k, v in decode(state["collector"]).items():
            setattr(self.collector, k, v)
        self.recent.extend((float(r), int(ok)) for r, ok in json.loads(state["recent"]))
        if self.outcomes is not None and state.get("scenario_outcomes"):
            self.outcomes.load_json(state["scenario_outcomes"])

    def checkpoint(self) -> Path:
        return write_checkpoint(self.run_dir, self.state_dict())

    # ---- pieces of the loop
    def update(self, pretraining: bool = False) -> dict[str, Any]:
        """One gradient update on a minibatch of the replay memories (the demonstrations only
        while pre-training), on the path `replay` chose, then one step of the weight average;
        the loss parts, floats or tensors."""
        info = self._gradient_update(pretraining)
        self.agent.average_step()
        return info

    def _gradient_update(self, pretraining: bool) -> dict[str, Any]:
        if self.replay_path == "host":
            return self.agent.update(self.sample(pretraining))
        if self._device_update is None:
            assert isinstance(self.replay, DeviceReplay)
            demo = None
            if self.demo is not None:
                demo = DeviceReplay.from_memory(self.demo, self.device)
            self._device_update = DeviceUpdate(
                self.agent,
                self.replay,
                demo,
                generator=self.replay_gen,
                graph=self.cuda_graph,
                index_rng=self.rng if self.replay_path == "device-numpy" else None,
            )
        return self._device_update(pretraining)

    def dagger_round_labels(self) -> dict[str, Any]:
        """The next DAgger round: the current network, saved as `dagger_student.pt`, flies new
        episodes behind its layer; the teacher's labels on its states join the demonstrations."""
        self.dagger_round += 1
        student = self.save_policies("dagger_student")
        part, info = label_part(self.cfg, self.reward_cfg, str(student), self.dagger_round)
        assert self.demo is not None
        self.demo = self.demo.extended(*part)
        self._device_update = None  # rebuilt on the grown memory at the next update
        self.demo_info.setdefault("dagger_rounds", []).append(info)
        return info

    def device_metadata(self) -> dict[str, Any]:
        """Where this run trains (run metadata: config.json and the saved policies)."""
        return {
            "requested": self.cfg.device,
            "used": describe_device(self.device),
            "replay": self.replay_path,
            "cuda_graph": self.cuda_graph,
            "torch": torch.__version__,
        }

    def cpu_network(self) -> Any:
        """The network that flies (`agent.policy_net`: the weight average, else the online
        network) on the CPU, itself there, else a copy of its current weights: what the periodic
        evaluation and the DAgger student fly and the policy files hold."""
        net = self.agent.policy_net
        if self.device.type == "cpu":
            return net
        if self._q_cpu is None:
            self._q_cpu = copy.deepcopy(net).cpu()
        self._q_cpu.load_state_dict(net.state_dict())
        return self._q_cpu

    def sample(self, pretraining: bool = False) -> ReplaySample:
        """One update's minibatch, drawn from the memories in the order of `minibatch_plan`."""
        cfg = self.cfg
        plan = plan_of(cfg, has_demo=self.demo is not None, pretraining=pretraining)
        memories = {REPLAY: self.replay, DEMO: self.demo}
        out: ReplaySample | None = None
        for memory, rows in plan.parts:
            part = memories[memory].sample(rows, self.rng)
            out = part if out is None else concat_samples(out, part)
        assert out is not None
        return out

    def evaluate(self, episodes: int | None = None, seed: int | None = None) -> dict[str, float]:
        """Greedy evaluation on seeded episodes (the periodic one of `run`)."""
        return greedy_evaluation(self.cpu_network(), self.cfg, episodes, seed)

    def save_policies(self, name: str, extra: dict[str, Any] | None = None) -> Path:
        meta = policy_metadata(
            self.cfg,
            {
                "updates": self.agent.updates,
                "episodes": self.c.episodes,
                "env_steps": self.c.env_steps,
                "wall_s": self.c.wall_s,
                "demos": self.demo_info,
                "device": self.device_metadata(),
                **(extra or {}),
            },
        )
        return save_policy(self.run_dir / name, self.cpu_network(), self.runtime_config(), meta)

    def runtime_config(self) -> RuntimeConfig:
        """What the trained network flies behind (`runtime_config_for`)."""
        return runtime_config_for(self.cfg)


def train(
    cfg: TrainConfig,
    run_dir: Path | None = None,
    quiet: bool = False,
    on_eval: EvalCallback | None = None,
) -> dict[str, Any]:
    """Train from scratch, data first: the demonstrations (`prepare_demonstrations`), then a
    `Trainer` on them; returns the run's summary (see `Trainer.run`)."""
    check_config(cfg)
    run_dir = run_dir or run_folder(cfg)
    demos = prepare_demonstrations(cfg, run_dir)
    return Trainer(cfg, run_dir, quiet, on_eval, demos=demos).run()
