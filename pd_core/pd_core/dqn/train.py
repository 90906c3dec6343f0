"""The training loop of `pd-train`: batched envs, two replay memories, logs, checkpoints, resume.

A run folder `runs/<preset>__<seed>__<time>/` holds config.json, episodes.csv (one row per
finished training episode: Fig. 5), metrics.csv (losses, epsilon, running return and success
rate), evals.csv (periodic greedy evaluations against wall time), curves.png, checkpoint.pt
(resumable), and the policies best.pt/.json (best periodic evaluation) and final.pt/.json.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import os
import time
from collections import deque
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from pd_core.config import MAX_EPISODE_TIME_S, REWARD, STATE_SCALE, RewardConfig
from pd_core.dqn.agent import DQNAgent, concat_samples, epsilon_at
from pd_core.dqn.config import TrainConfig
from pd_core.dqn.network import QNetwork
from pd_core.dqn.replay import DemoMemory, NStepCollector, ReplayMemory, nstep_from_episodes
from pd_core.env import PoweredDescentVectorEnv
from pd_core.policy import code_version, expected_metadata, save_policy
from pd_core.reward import reward as shaped_reward
from pd_core.state import scale_state

CHECKPOINT = "checkpoint.pt"


def make_vector_env(
    num_envs: int,
    disturbance: bool = True,
    max_time_s: float = MAX_EPISODE_TIME_S,
    reward_cfg: RewardConfig = REWARD,
    autoreset: bool = True,
) -> PoweredDescentVectorEnv:
    """The env factory shared by training and evaluation (Table 3, disturbances on)."""
    return PoweredDescentVectorEnv(
        num_envs,
        disturbance=disturbance,
        max_time_s=max_time_s,
        reward_cfg=reward_cfg,
        autoreset=autoreset,
    )


def training_reward(cfg: TrainConfig) -> RewardConfig:
    """Eq. 12 with beta scaled by `fuel_weight` (1.0: the paper's reward)."""
    return replace(REWARD, beta=REWARD.beta * cfg.fuel_weight)


class NetActor:
    """Greedy actions of a Q-network on physical states (what evaluation calls)."""

    def __init__(self, net: QNetwork) -> None:
        self.net = net

    def act_batch(self, states: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            q = self.net(torch.from_numpy(scale_state(states)))
        return q.argmax(dim=1).numpy()


# --- demonstrations ------------------------------------------------------------------------


def _relabel_rewards(
    next_states: np.ndarray, actions: np.ndarray, reward_cfg: RewardConfig
) -> np.ndarray:
    from pd_core.actions import DEFAULT_ACTIONS

    thrust = DEFAULT_ACTIONS.thrust(actions)
    return shaped_reward(next_states[:, 0:3], next_states[:, 3:6], thrust, reward_cfg)


def demo_transitions(
    states: np.ndarray,
    actions: np.ndarray,
    next_states: np.ndarray,
    dones: np.ndarray,
    episode: np.ndarray,
    cfg: TrainConfig,
    reward_cfg: RewardConfig,
) -> tuple[np.ndarray, ...]:
    """Scaled n-step transitions of physical demonstration steps (rewards recomputed, Eq. 12)."""
    rewards = _relabel_rewards(next_states, actions, reward_cfg)
    return nstep_from_episodes(
        scale_state(states),
        np.asarray(actions, dtype=np.int64),
        rewards,
        scale_state(next_states),
        np.asarray(dones, dtype=bool),
        np.asarray(episode),
        cfg.gamma,
        cfg.n_step,
    )


def controller_demos(
    name: str, n_episodes: int, seed: int, reward_cfg: RewardConfig
) -> dict[str, np.ndarray]:
    """Physical 1-step transitions of a reference controller flying the disturbed env."""
    from pd_core.controllers import make_controller
    from pd_core.evaluate import rollout

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
    return {
        "states": np.concatenate(s),
        "actions": np.concatenate(a),
        "next_states": np.concatenate(nx),
        "dones": np.concatenate(d),
        "episode": np.concatenate(ep),
        "success_rate": np.array(float(np.mean(ro.landed))),
    }


def build_demo_memory(cfg: TrainConfig, reward_cfg: RewardConfig) -> tuple[DemoMemory | None, dict]:
    """The demonstration memory from the demos file and/or controller episodes."""
    parts: list[tuple[np.ndarray, ...]] = []
    info: dict[str, Any] = {}
    if cfg.batch_demo > 0 and cfg.demos:
        path = Path(cfg.demos)
        if not path.is_file():
            raise FileNotFoundError(
                f"demonstration file {path} not found (make it with `pd-ocp demos`, or pass "
                "--demos '' to train without the file)"
            )
        from pd_core.demos import load_demos  # type: ignore[import-not-found]

        ds, meta = load_demos(path)
        parts.append(
            demo_transitions(
                ds.states, ds.actions, ds.next_states, ds.dones, ds.episode, cfg, reward_cfg
            )
        )
        info["file"] = {"path": str(path), "transitions": len(ds.actions)}
    if cfg.batch_demo > 0 and cfg.controller_demo_episodes > 0:
        c = controller_demos(
            cfg.controller, cfg.controller_demo_episodes, cfg.seed + 50_000_000, reward_cfg
        )
        # controller episodes get ids disjoint from the file's
        parts.append(
            demo_transitions(
                c["states"],
                c["actions"],
                c["next_states"],
                c["dones"],
                c["episode"],
                cfg,
                reward_cfg,
            )
        )
        info["controller"] = {
            "name": cfg.controller,
            "episodes": cfg.controller_demo_episodes,
            "transitions": len(c["actions"]),
            "success_rate": float(c["success_rate"]),
        }
    if not parts:
        return None, info
    cat = [np.concatenate([p[k] for p in parts]) for k in range(5)]
    return DemoMemory.fill(*cat), info


# --- logging ---------------------------------------------------------------------------------


class CsvLog:
    def __init__(self, path: Path, header: list[str]) -> None:
        new = not path.exists()
        self.f = path.open("a", newline="")
        self.w = csv.writer(self.f)
        if new:
            self.w.writerow(header)

    def row(self, *values: Any) -> None:
        self.w.writerow([f"{v:.6g}" if isinstance(v, float) else v for v in values])

    def flush(self) -> None:
        self.f.flush()

    def close(self) -> None:
        self.f.close()


def run_folder(cfg: TrainConfig) -> Path:
    if cfg.run_dir:
        return Path(cfg.run_dir)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    return Path("runs") / f"{cfg.preset}__{cfg.seed}__{stamp}"


def policy_metadata(cfg: TrainConfig, extra: dict[str, Any] | None = None) -> dict[str, Any]:
    return {
        "training": {
            "config": cfg.to_dict(),
            "seed": cfg.seed,
            "state_scale": STATE_SCALE.tolist(),
            **(extra or {}),
        }
    }


# --- the loop --------------------------------------------------------------------------------


@dataclasses.dataclass
class Counters:
    env_steps: int = 0
    episodes: int = 0
    successes: int = 0
    wall_s: float = 0.0  # summed over resumed segments
    update_credit: float = 0.0
    last_eval_s: float = 0.0
    last_ckpt_s: float = 0.0
    best_eval: tuple[float, float] = (-1.0, 0.0)  # (success rate, -median fuel)


class Trainer:
    """Holds everything a run needs; `run()` trains until a stop criterion."""

    def __init__(self, cfg: TrainConfig, run_dir: Path | None = None, quiet: bool = False):
        self.cfg = cfg
        self.quiet = quiet
        torch.set_num_threads(max(cfg.torch_threads, 1))
        torch.manual_seed(cfg.seed)
        self.rng = np.random.default_rng(cfg.seed)
        self.reward_cfg = training_reward(cfg)
        self.agent = DQNAgent(cfg)
        self.replay = ReplayMemory(cfg.buffer_size)
        self.demo, self.demo_info = build_demo_memory(cfg, self.reward_cfg)
        self.run_dir = run_dir or run_folder(cfg)
        self.run_dir.mkdir(parents=True, exist_ok=True)
        if cfg.input_norm_init:
            self.agent.init_input_normalisation(self._normalisation_states())
        self.env = make_vector_env(cfg.num_envs, reward_cfg=self.reward_cfg)
        self.obs, _ = self.env.reset(seed=cfg.seed * 1000)
        self.collector = NStepCollector(cfg.num_envs, cfg.n_step, cfg.gamma)
        self.ep_return = np.zeros(cfg.num_envs)
        self.c = Counters()
        self.recent = deque(maxlen=100)  # (return, landed)
        self.last_info: dict[str, float] = {}
        self.pretrained = 0

    def _normalisation_states(self) -> np.ndarray:
        """Scaled states to standardise the inputs with: the demonstrations', or else the
        states the reference controller visits (statistics only, not stored as transitions)."""
        if self.demo is not None and len(self.demo) > 0:
            return self.demo.obs[: len(self.demo)]
        from pd_core.controllers import make_controller
        from pd_core.evaluate import rollout

        ro = rollout(
            make_controller(self.cfg.controller),
            50,
            self.cfg.seed + 60_000_000,
            keep_trajectories=50,
        )
        return scale_state(np.concatenate(ro.trajectories))

    # ---- checkpoints
    def checkpoint(self) -> Path:
        env = self.env
        c = self.c
        state = {
            "metadata": json.dumps(
                {
                    **expected_metadata(),
                    "network": self.agent.q.shape_metadata(),
                    "code_version": code_version(),
                    "seed": self.cfg.seed,
                }
            ),
            "config": json.dumps(self.cfg.to_dict()),
            "agent": self.agent.state_dict(),
            "replay": self.replay.state_dict(),
            "demo": self.demo.state_dict() if self.demo is not None else None,
            "demo_info": json.dumps(self.demo_info),
            "counters": json.dumps(dataclasses.asdict(c)),
            "pretrained": self.pretrained,
            "rng": json.dumps(self.rng.bit_generator.state),
            "torch_rng": torch.get_rng_state(),
            "env": {
                "states": torch.from_numpy(env.states.copy()),
                "initial_states": torch.from_numpy(env.initial_states.copy()),
                "steps": torch.from_numpy(env.steps.copy()),
                "knots": torch.from_numpy(env._knots.copy()),
                "rngs": json.dumps([r.bit_generator.state for r in env._rngs]),
            },
            "obs": torch.from_numpy(self.obs.copy()),
            "ep_return": torch.from_numpy(self.ep_return.copy()),
            "collector": {
                k: torch.from_numpy(getattr(self.collector, k).copy())
                for k in ("obs", "act", "rew", "count")
            },
            "recent": json.dumps(list(self.recent)),
        }
        path = self.run_dir / CHECKPOINT
        tmp = path.with_suffix(".tmp")
        torch.save(state, tmp)
        os.replace(tmp, path)
        return path

    @classmethod
    def resume(cls, path: str | Path, overrides: dict[str, Any] | None = None) -> Trainer:
        p = Path(path)
        ckpt = p / CHECKPOINT if p.is_dir() else p
        state = torch.load(ckpt, map_location="cpu", weights_only=True)
        saved = json.loads(state.get("metadata", "{}"))
        diffs = [
            f"{k}: checkpoint has {saved.get(k)!r}, code has {v!r}"
            for k, v in expected_metadata().items()
            if k in saved and saved[k] != v
        ]
        if diffs:
            raise ValueError(f"{ckpt}: checkpoint does not match the code: " + "; ".join(diffs))
        d = json.loads(state["config"])
        d["hidden"] = tuple(d["hidden"])
        d.update(overrides or {})
        cfg = TrainConfig(**d)
        self = cls.__new__(cls)
        self.cfg = cfg
        self.quiet = False
        torch.set_num_threads(max(cfg.torch_threads, 1))
        self.run_dir = ckpt.parent
        self.reward_cfg = training_reward(cfg)
        self.agent = DQNAgent(cfg)
        self.agent.load_state_dict(state["agent"])
        self.replay = ReplayMemory(cfg.buffer_size)
        self.replay.load_state_dict(state["replay"])
        if state["demo"] is not None:
            self.demo = DemoMemory(1)
            self.demo.load_state_dict(state["demo"])
        else:
            self.demo = None
        self.demo_info = json.loads(state["demo_info"])
        c = json.loads(state["counters"])
        c["best_eval"] = tuple(c["best_eval"])
        self.c = Counters(**c)
        self.pretrained = int(state["pretrained"])
        self.rng = np.random.default_rng()
        self.rng.bit_generator.state = json.loads(state["rng"])
        torch.set_rng_state(state["torch_rng"])
        self.env = make_vector_env(cfg.num_envs, reward_cfg=self.reward_cfg)
        e = state["env"]
        self.env.states = e["states"].numpy().copy()
        self.env.initial_states = e["initial_states"].numpy().copy()
        self.env.steps = e["steps"].numpy().copy()
        self.env._knots = e["knots"].numpy().copy()
        for r, s in zip(self.env._rngs, json.loads(e["rngs"]), strict=True):
            r.bit_generator.state = s
        self.obs = state["obs"].numpy().copy()
        self.ep_return = state["ep_return"].numpy().copy()
        self.collector = NStepCollector(cfg.num_envs, cfg.n_step, cfg.gamma)
        for k, v in state["collector"].items():
            setattr(self.collector, k, v.numpy().copy())
        self.recent = deque((tuple(x) for x in json.loads(state["recent"])), maxlen=100)
        self.last_info = {}
        return self

    # ---- pieces of the loop
    def sample(self, pretraining: bool = False) -> Any:
        cfg = self.cfg
        if pretraining:
            return self.demo.sample(cfg.batch_agent + cfg.batch_demo, self.rng)
        a = self.replay.sample(cfg.batch_agent, self.rng)
        if self.demo is None or cfg.batch_demo == 0:
            return a
        return concat_samples(a, self.demo.sample(cfg.batch_demo, self.rng))

    def evaluate(self, episodes: int | None = None, seed: int | None = None) -> dict[str, float]:
        from pd_core.evaluate import rollout, summarise

        ro = rollout(
            NetActor(self.agent.q),
            episodes or self.cfg.eval_episodes,
            self.cfg.eval_seed if seed is None else seed,
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

    def save_policies(self, name: str, extra: dict[str, Any] | None = None) -> Path:
        meta = policy_metadata(
            self.cfg,
            {
                "updates": self.agent.updates,
                "episodes": self.c.episodes,
                "env_steps": self.c.env_steps,
                "wall_s": self.c.wall_s,
                "demos": self.demo_info,
                **(extra or {}),
            },
        )
        return save_policy(self.run_dir / name, self.agent.q, meta)

    def run(self) -> dict[str, Any]:
        cfg = self.cfg
        rd = self.run_dir
        (rd / "config.json").write_text(
            json.dumps({**cfg.to_dict(), "code_version": code_version()}, indent=2) + "\n"
        )
        ep_log = CsvLog(
            rd / "episodes.csv",
            [
                "episode",
                "wall_s",
                "env_steps",
                "updates",
                "return",
                "landed",
                "fuel_kg",
                "k_velocity_mps",
                "epsilon",
            ],
        )
        m_log = CsvLog(
            rd / "metrics.csv",
            [
                "wall_s",
                "env_steps",
                "updates",
                "episodes",
                "epsilon",
                "loss",
                "td_loss",
                "margin_loss",
                "q_mean",
                "return_100",
                "success_100",
            ],
        )
        ev_log = CsvLog(
            rd / "evals.csv",
            [
                "wall_s",
                "updates",
                "episodes",
                "success_rate",
                "soft_landing_rate",
                "fuel_median",
                "pos_median",
                "kvel_min",
                "mean_return",
            ],
        )
        bar = None
        if cfg.progress and not self.quiet:
            from tqdm import tqdm

            bar = tqdm(total=cfg.episodes, initial=self.c.episodes, unit="ep", smoothing=0.05)
        t0 = time.perf_counter() - self.c.wall_s
        now = lambda: time.perf_counter() - t0  # noqa: E731
        # DQfD pre-training on demonstrations only
        while self.demo is not None and self.pretrained < cfg.pretrain_updates:
            self.last_info = self.agent.update(self.sample(pretraining=True))
            self.pretrained += 1
            if self.pretrained % 1000 == 0:
                self.c.wall_s = now()
                m_log.row(
                    self.c.wall_s,
                    0,
                    self.agent.updates,
                    0,
                    1.0,
                    *self._loss_row(),
                    float("nan"),
                    float("nan"),
                )
                m_log.flush()
                if bar is not None:
                    bar.set_postfix_str(f"pretrain {self.pretrained}/{cfg.pretrain_updates}")
                t = now()
                if cfg.eval_every_s > 0 and t - self.c.last_eval_s >= cfg.eval_every_s:
                    self._periodic_eval(ev_log, now)
                if t - self.c.last_ckpt_s >= cfg.checkpoint_every_s:
                    self.c.wall_s = t
                    self.c.last_ckpt_s = t
                    self.checkpoint()
        if cfg.lr_finetune > 0 and self.pretrained >= cfg.pretrain_updates:
            for group in self.agent.opt.param_groups:
                group["lr"] = cfg.lr_finetune
        last_log = now()
        stop_reason = ""
        while True:
            if self.c.episodes >= cfg.episodes:
                stop_reason = "episodes"
            elif cfg.max_minutes > 0 and now() >= 60.0 * cfg.max_minutes:
                stop_reason = "max_minutes"
            elif cfg.max_updates > 0 and self.agent.updates >= cfg.max_updates:
                stop_reason = "max_updates"
            if stop_reason:
                break
            eps = epsilon_at(self.c.episodes, cfg)
            actions = self.agent.act(self.obs, eps, self.rng)
            nobs, r, term, trunc, info = self.env.step(actions)
            self.c.env_steps += cfg.num_envs
            self.ep_return += r
            done = term | trunc
            tr = self.collector.step(self.obs, actions, r, nobs, term, trunc, info.get("final_obs"))
            self.replay.add(*tr)
            for i in np.flatnonzero(done):
                self.c.episodes += 1
                ok = bool(info["landed"][i])
                self.c.successes += ok
                fs = info["final_state"][i]
                ep_log.row(
                    self.c.episodes,
                    now(),
                    self.c.env_steps,
                    self.agent.updates,
                    float(self.ep_return[i]),
                    int(ok),
                    float(info["fuel_kg"][i]),
                    float(fs[5]),
                    eps,
                )
                self.recent.append((float(self.ep_return[i]), int(ok)))
                self.ep_return[i] = 0.0
                if bar is not None:
                    bar.update(1)
            self.obs = nobs
            if len(self.replay) >= cfg.learning_starts:
                self.c.update_credit += cfg.updates_per_step
                while self.c.update_credit >= 1.0:
                    self.last_info = self.agent.update(self.sample())
                    self.c.update_credit -= 1.0
            t = now()
            if t - last_log >= 10.0:
                last_log = t
                self.c.wall_s = t
                ret = np.mean([x[0] for x in self.recent]) if self.recent else float("nan")
                suc = np.mean([x[1] for x in self.recent]) if self.recent else float("nan")
                m_log.row(
                    t,
                    self.c.env_steps,
                    self.agent.updates,
                    self.c.episodes,
                    eps,
                    *self._loss_row(),
                    float(ret),
                    float(suc),
                )
                m_log.flush()
                ep_log.flush()
                if bar is not None:
                    bar.set_postfix_str(
                        f"eps {eps:.3f} succ100 {suc:.2f} loss {self.last_info.get('loss', 0):.3g}"
                        f" upd {self.agent.updates}"
                    )
            if cfg.eval_every_s > 0 and t - self.c.last_eval_s >= cfg.eval_every_s:
                self._periodic_eval(ev_log, now)
            if t - self.c.last_ckpt_s >= cfg.checkpoint_every_s:
                self.c.wall_s = t
                self.c.last_ckpt_s = t
                self.checkpoint()
        self.c.wall_s = now()
        if cfg.eval_every_s > 0:
            self._periodic_eval(ev_log, now)
        final = self.save_policies("final")
        self.checkpoint()
        for log in (ep_log, m_log, ev_log):
            log.close()
        if bar is not None:
            bar.close()
        try:
            from pd_core.plots import training_curves

            training_curves(rd, rd / "curves.png")
        except Exception as exc:  # noqa: BLE001 - plotting must never lose a trained model
            print(f"pd-train: could not plot curves: {exc}")
        return {
            "run_dir": str(rd),
            "stop_reason": stop_reason,
            "episodes": self.c.episodes,
            "successes": self.c.successes,
            "env_steps": self.c.env_steps,
            "updates": self.agent.updates,
            "wall_s": self.c.wall_s,
            "final_policy": str(final),
            "best_eval": list(self.c.best_eval),
        }

    def _loss_row(self) -> list[float]:
        li = self.last_info
        return [li.get(k, float("nan")) for k in ("loss", "td_loss", "margin_loss", "q_mean")]

    def _periodic_eval(self, ev_log: CsvLog, now: Any) -> None:
        ev = self.evaluate()
        t = now()
        self.c.last_eval_s = t
        self.c.wall_s = t
        ev_log.row(t, self.agent.updates, self.c.episodes, *ev.values())
        ev_log.flush()
        key = (ev["success_rate"], -ev["fuel_median"])
        if key > tuple(self.c.best_eval):
            self.c.best_eval = key
            self.save_policies("best", {"periodic_eval": ev})


def train(cfg: TrainConfig, run_dir: Path | None = None, quiet: bool = False) -> dict[str, Any]:
    """Train from scratch; returns a summary dict (see `Trainer.run`)."""
    return Trainer(cfg, run_dir, quiet).run()
