"""The device-resident training loop (`pd-train --loop device`): Table 2's DQN for one or several
agents at once, with the replay memories, the minibatch draws and whole blocks of updates on
the device the networks live on.

Mechanism, per batched env step of every agent (each agent its own `num_envs` envs, seeds,
epsilon schedule, memories and run folder):

1. act: one forward pass of every online network on its agent's observations (one CUDA graph on
   cuda), greedy actions read back, epsilon-greedy on the host with the agent's numpy generator
   exactly as `DQNAgent.act` draws;
2. the vectorised numba env steps on the CPU; the transitions (n = 1, as `NStepCollector`
   orders them) are written into one device tensor that holds every agent's demonstrations and
   FIFO replay memory, 17 floats a row;
3. the `updates_per_step` updates this step owes (K, one per transition at the paper's ratio)
   run as one block: the K x A x B minibatch indices are drawn on the device (uniform over each
   memory's size, agent rows then demonstration rows as `Trainer.sample` takes them), the rows
   gathered once, then K updates of `pd_core.dqn.stacked.StackedQ` (forward, Eq. 11's TD
   gradient, backward, RMSProp, the target copy on the update that is a multiple of n_T), all
   one CUDA graph on cuda.

With `overlap` (the default on cuda) a step's block is launched after the next step's actions
are chosen, so the GPU runs it while the CPU steps the envs: the updates see exactly the
transitions the reference loop's would, and the acting networks are one block (K updates)
older. Without it (the CPU default) the order is the reference loop's, act, step, update;
with `host_indices` the minibatch indices come from each agent's numpy generator in the
reference loop's order, so a run reproduces `Trainer`'s (the tests compare them).

Counts are the reference loop's: an agent's env transitions, episodes and updates (one per
transition once `learning_starts` transitions are stored; an agent that reaches its `episodes`
or `max_updates` stops learning, exactly at the count, while the others go on). Evaluations,
logs (episodes.csv, metrics.csv, evals.csv), curves.png, best and final policy files are those of
`pd_core.dqn.train`, one run folder per agent; `checkpoint.pt` (`pd_core.dqn.device_checkpoint`)
in the loop's folder every `checkpoint_every_s` and at the end resumes the whole loop.
"""

from __future__ import annotations

import json
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from pd_core.dqn.agent import epsilon_at
from pd_core.dqn.checkpoint import write_checkpoint
from pd_core.dqn.config import TrainConfig, check_config, preset, training_reward
from pd_core.dqn.demo_file import prepare_demonstrations
from pd_core.dqn.device import describe_device, resolve_device
from pd_core.dqn.device_checkpoint import loop_state, read_loop_checkpoint, restore
from pd_core.dqn.minibatch import DEMO, REPLAY, MinibatchPlan, plan_of
from pd_core.dqn.network import QNetwork
from pd_core.dqn.replay import ReplayMemory
from pd_core.dqn.run_log import RunLogs, run_folder
from pd_core.dqn.stacked import StackedQ, td_output_grad
from pd_core.dqn.train import (
    greedy_evaluation,
    policy_metadata,
    runtime_config_for,
)
from pd_core.plots import training_curves
from pd_core.runtime.policy_file import code_version, save_policy
from pd_core.vector_env import make_vector_env

ROW = 17
"""floats per stored transition: obs (7), action, reward, discount, next_obs (7)"""
_OBS, _ACT, _REW, _DISC, _NEXT = slice(0, 7), 7, 8, 9, slice(10, 17)
METRICS_PERIOD_S = 10.0
"""metrics.csv rows and progress-bar updates this often"""
STATUS_PERIOD_S = 30.0
"""without a progress bar, a status line on stdout this often"""

# Table 2's algorithm: what the device loop runs, and the value each other option must have.
_TABLE2_ONLY = {
    "optimizer": "rmsprop",
    "loss": "mse",
    "double_dqn": False,
    "n_step": 1,
    "margin": 0.0,
    "weight_average": 0.0,
    "grad_clip": 0.0,
    "near_pad": False,
    "input_norm_init": False,
    "activation": "tanh",
    "pretrain_updates": 0,
    "dagger_rounds": 0,
    "lr_finetune": 0.0,
    "init_policy": "",
    "scenario_sampling": "uniform",
    "resume": "",
}
# ... and what every agent trained together must share.
_SHARED = ("hidden", "lr", "num_envs", "updates_per_step", "learning_starts", "target_period")


def device_loop_unsupported(cfg: TrainConfig) -> str:
    """ "" if the device loop runs `cfg`, else the first reason it does not (one line)."""
    for name, value in _TABLE2_ONLY.items():
        if getattr(cfg, name) != value:
            return f"the device loop runs Table 2's algorithm: {name} must be {value!r}"
    if cfg.updates_per_step != int(cfg.updates_per_step):
        return "the device loop needs a whole number of updates_per_step"
    if cfg.batch_demo and not cfg.demos:
        return "the device loop takes demonstrations from a file (demos)"
    return ""


def uses_device_loop(cfg: TrainConfig) -> bool:
    """Whether `pd-train` trains `cfg` with this loop: `loop` device, or auto on cuda for
    Table 2's algorithm (or with more `agents`, which only this loop trains)."""
    if cfg.loop != "auto":
        return cfg.loop == "device"
    if cfg.agents.strip():
        return True
    on_cuda = cfg.device == "cuda" or (cfg.device == "auto" and torch.cuda.is_available())
    return on_cuda and not device_loop_unsupported(cfg)


def agent_configs(
    cfg: TrainConfig, overrides: dict[str, Any]
) -> tuple[list[TrainConfig], list[Path]]:
    """`cfg` and the agents its `agents` names (each its preset with `overrides` and its seed),
    with their run folders: `cfg`'s alone, or <run folder>/<preset>__<seed> each."""
    cfgs = [cfg]
    for item in filter(None, (x.strip() for x in cfg.agents.split(","))):
        name, _, seed = item.partition(":")
        cfgs.append(preset(name, **{**overrides, "seed": int(seed), "agents": ""}))
    base = run_folder(cfg)
    if len(cfgs) == 1:
        return cfgs, [base]
    return cfgs, [base / f"{c.preset}__{c.seed}" for c in cfgs]


def check_agents(cfgs: list[TrainConfig]) -> None:
    """ValueError unless the device loop can train `cfgs` together."""
    if not cfgs:
        raise ValueError("the device loop needs at least one agent")
    for cfg in cfgs:
        check_config(cfg)
        if reason := device_loop_unsupported(cfg):
            raise ValueError(f"{cfg.preset} seed {cfg.seed}: {reason}")
        for name in _SHARED:
            if getattr(cfg, name) != getattr(cfgs[0], name):
                raise ValueError(f"agents trained together must share {name}")
        if cfg.batch_agent + cfg.batch_demo != cfgs[0].batch_agent + cfgs[0].batch_demo:
            raise ValueError("agents trained together must share the minibatch size k + k_demo")
    names = [(c.preset, c.seed) for c in cfgs]
    if len(set(names)) != len(names):
        raise ValueError(f"agents trained together must differ in preset or seed: {names}")


@dataclass
class AgentState:
    """One agent's host side: config, envs, generators, counters, logs."""

    cfg: TrainConfig
    run_dir: Path
    rng: np.random.Generator
    env: Any
    obs: np.ndarray
    demo_size: int
    demo_info: dict[str, Any]
    logs: RunLogs
    ep_return: np.ndarray
    env_steps: int = 0
    episodes: int = 0
    successes: int = 0
    updates: int = 0
    replay_pos: int = 0
    replay_size: int = 0
    learning: bool = True  # False once it reached its episodes or max_updates
    epsilon: float = 0.0  # the exploration rate of the last actions
    last_eval_s: float = 0.0
    last_eval_updates: int = -1
    best_eval: tuple[float, float] = (-1.0, 0.0)
    recent: deque = field(default_factory=lambda: deque(maxlen=100))


class _Captured:
    """`fn()` eagerly, or on cuda as a CUDA graph captured after a few eager warm-up calls on a
    side stream (the calls before capture do their work too)."""

    WARMUP = 2

    def __init__(self, fn: Callable[[], None], graph: bool) -> None:
        self.fn, self.graph, self.calls = fn, graph, 0
        self.cuda_graph: Any = None

    def __call__(self) -> None:
        if not self.graph:
            self.fn()
        elif self.cuda_graph is not None:
            self.cuda_graph.replay()
        elif self.calls < self.WARMUP:
            side = torch.cuda.Stream()
            side.wait_stream(torch.cuda.current_stream())
            with torch.cuda.stream(side):
                self.fn()
            torch.cuda.current_stream().wait_stream(side)
        else:
            self.cuda_graph = torch.cuda.CUDAGraph()
            with torch.cuda.graph(self.cuda_graph):
                self.fn()
            self.cuda_graph.replay()  # capture records the work, it does not run it
        self.calls += 1


class DeviceLoop:
    """Trains `cfgs` (one per agent) together on `device`; `run()` until every agent stops."""

    def __init__(
        self,
        cfgs: list[TrainConfig],
        run_dirs: list[Path] | None = None,
        device: str | None = None,
        overlap: bool | None = None,
        host_indices: bool = False,
        quiet: bool = False,
        capacity: int | None = None,
        home: Path | None = None,
    ) -> None:
        check_agents(cfgs)
        t_start = time.perf_counter()
        self.cfgs, self.quiet = cfgs, quiet
        self.device = resolve_device(device or cfgs[0].device)
        self.graph = self.device.type == "cuda"
        self.overlap = self.graph if overlap is None else overlap
        self.host_indices = host_indices
        first = cfgs[0]
        torch.set_num_threads(max(first.torch_threads, 1))
        self.n_envs = first.num_envs
        self.k = int(first.updates_per_step)
        self.batch = first.batch_agent + first.batch_demo
        nets, demos, self.agents = [], [], []
        for i, cfg in enumerate(cfgs):
            torch.manual_seed(cfg.seed)  # the reference loop's first draw: the same weights
            nets.append(QNetwork(7, 147, tuple(cfg.hidden)))
            run_dir = Path(run_dirs[i]) if run_dirs else run_folder(cfg)
            run_dir.mkdir(parents=True, exist_ok=True)
            demo, info, _, _ = prepare_demonstrations(cfg, run_dir)  # data first
            demos.append(demo)
            env = make_vector_env(
                cfg.num_envs, reward_cfg=training_reward(cfg), dispersions=cfg.dispersions
            )
            obs, _ = env.reset(seed=cfg.seed * 1000)
            self.agents.append(
                AgentState(
                    cfg=cfg,
                    run_dir=run_dir,
                    rng=np.random.default_rng(cfg.seed),
                    env=env,
                    obs=obs,
                    demo_size=len(demo) if demo is not None and cfg.batch_demo else 0,
                    demo_info=info,
                    logs=RunLogs(run_dir),
                    ep_return=np.zeros(cfg.num_envs),
                )
            )
        self.q = StackedQ.from_networks(nets, first.lr, self.device)
        self._init_memory(demos, capacity)
        self._init_buffers()
        self.gen = torch.Generator(device=self.device)
        self.gen.manual_seed(first.seed)
        self._bar: Any = None
        self._last_print = 0.0
        self.pending = [0] * len(self.agents)
        first_dir = self.agents[0].run_dir
        self.home = Path(home or (first_dir if len(self.agents) == 1 else first_dir.parent))
        self.home.mkdir(parents=True, exist_ok=True)
        self.wall_s = time.perf_counter() - t_start
        self._t0 = t_start

    # ---- device memory
    def _init_memory(self, demos: list[ReplayMemory | None], capacity: int | None) -> None:
        """One (A * (D + C), 17) tensor: per agent D demonstration rows, then a C-row FIFO."""
        self.capacity = capacity or max(c.buffer_size for c in self.cfgs)
        self.demo_rows = max(a.demo_size for a in self.agents)
        self.region = self.demo_rows + self.capacity
        self.store = torch.zeros((len(self.agents) * self.region, ROW), device=self.device)
        for i, (agent, demo) in enumerate(zip(self.agents, demos, strict=True)):
            if agent.demo_size:
                rows = _pack(
                    demo.obs[: agent.demo_size],
                    demo.actions[: agent.demo_size],
                    demo.rewards[: agent.demo_size],
                    demo.next_obs[: agent.demo_size],
                    demo.discounts[: agent.demo_size],
                )
                start = i * self.region
                self.store[start : start + agent.demo_size] = torch.from_numpy(rows)

    def _column_plan(self) -> tuple[np.ndarray, np.ndarray]:
        """(memory size, first row) of every minibatch column (A, B): an agent's k rows from its
        replay memory, then its k_demo rows from its demonstrations."""
        size = np.zeros((len(self.agents), self.batch))
        base = np.zeros((len(self.agents), self.batch), dtype=np.int64)
        for i, agent in enumerate(self.agents):
            # a region: the demonstrations' rows first, then the replay memory's
            first = {REPLAY: i * self.region + self.demo_rows, DEMO: i * self.region}
            held = {REPLAY: agent.replay_size, DEMO: agent.demo_size}
            col = 0
            for memory, rows in self._plan(agent).parts:
                size[i, col : col + rows] = max(held[memory], 1)
                base[i, col : col + rows] = first[memory]
                col += rows
            size[i, col:], base[i, col:] = 1, i * self.region  # columns no draw fills
        return size, base

    @staticmethod
    def _plan(agent: AgentState) -> MinibatchPlan:
        return plan_of(agent.cfg, has_demo=agent.demo_size > 0)

    def _init_buffers(self) -> None:
        a, k, b, dev = len(self.agents), self.k, self.batch, self.device
        pin = self.graph  # page-locked host buffers: asynchronous copies to the GPU
        # the block's inputs from the host
        self.u = torch.zeros((k, a, b), dtype=torch.float64, device=dev)
        self.idx = torch.zeros((k, a, b), dtype=torch.int64, device=dev)
        self.size_col = torch.zeros((a, b), dtype=torch.float64, device=dev)
        self.last_col = torch.zeros((a, b), dtype=torch.int64, device=dev)
        self.base_col = torch.zeros((a, b), dtype=torch.int64, device=dev)
        self.flags = torch.zeros(k, dtype=torch.bool, device=dev)
        self.scale = torch.zeros((k, a, 1), device=dev)
        self.h_flags = torch.zeros(k, dtype=torch.bool, pin_memory=pin)
        self.h_scale = torch.zeros((k, a, 1), pin_memory=pin)
        self.h_plan = torch.zeros((3, a, b), dtype=torch.float64, pin_memory=pin)
        self.h_idx = torch.zeros((k, a, b), dtype=torch.int64, pin_memory=pin)
        # the block's working tensors
        self.x = self.q.inputs(2 * a, b, lead=(k,))
        self.actions = torch.zeros((k, a, b), dtype=torch.int64, device=dev)
        self.rewards = torch.zeros((k, a, b), device=dev)
        self.discounts = torch.zeros((k, a, b), device=dev)
        self.buf = self.q.buffers(2 * a, b)
        self.dq = torch.zeros((a, b, self.q.widths[-1]), device=dev)
        self.last_diff = torch.zeros((a, b), device=dev)
        self._block = _Captured(self._block_body, self.graph)
        # acting
        n = self.n_envs
        self.act_x = self.q.inputs(a, n)
        self.act_buf = self.q.buffers(a, n)
        self.act_out = torch.zeros((a, n), dtype=torch.int64, device=dev)
        self.h_obs = torch.zeros((a, n, 7), pin_memory=pin)
        self.h_act = torch.zeros((a, n), dtype=torch.int64, pin_memory=pin)
        self._act = _Captured(self._act_body, self.graph)
        # inserts
        self.h_rows = torch.zeros((a * n, ROW), pin_memory=pin)
        self.h_rows_at = torch.zeros(a * n, dtype=torch.int64, pin_memory=pin)

    # ---- the captured bodies
    def _act_body(self) -> None:
        q = self.q.forward(self.act_x, self.act_buf)
        torch.argmax(q, dim=2, out=self.act_out)

    def _block_body(self) -> None:
        k, a, b = self.idx.shape
        if not self.host_indices:
            torch.minimum((self.u * self.size_col).long(), self.last_col, out=self.idx)
            self.idx.add_(self.base_col)
        rows = self.store.index_select(0, self.idx.view(-1)).view(k, a, b, ROW)
        self.x[:, :a, :, :7].copy_(rows[..., _OBS])
        self.x[:, a:, :, :7].copy_(rows[..., _NEXT])
        self.actions.copy_(rows[..., _ACT])
        self.rewards.copy_(rows[..., _REW])
        self.discounts.copy_(rows[..., _DISC])
        for j in range(k):
            q = self.q.forward(self.x[j], self.buf)
            diff = td_output_grad(
                q, self.actions[j], self.rewards[j], self.discounts[j], self.scale[j], self.dq
            )
            self.q.backward(self.x[j], self.buf, self.dq)
            self.q.rmsprop_step()
            self.q.copy_target_where(self.flags[j])
        self.last_diff.copy_(diff)

    # ---- the steps of the loop
    def _now(self) -> float:
        return time.perf_counter() - self._t0

    def act(self) -> list[np.ndarray]:
        """Every agent's epsilon-greedy actions, as `DQNAgent.act` draws them."""
        for i, agent in enumerate(self.agents):
            self.h_obs[i].copy_(torch.from_numpy(agent.obs))
        self.act_x[:, :, :7].copy_(self.h_obs, non_blocking=True)
        self._act()
        self.h_act.copy_(self.act_out)  # waits for the GPU (and so for the previous block)
        out = []
        for i, agent in enumerate(self.agents):
            greedy = self.h_act[i].numpy().copy()
            eps = agent.epsilon = epsilon_at(agent.episodes, agent.cfg)
            if eps > 0.0:
                explore = agent.rng.random(len(greedy)) < eps
                rand = agent.rng.integers(0, self.q.widths[-1], size=len(greedy))
                greedy = np.where(explore, rand, greedy)
            out.append(greedy)
        return out

    def step(self, actions: list[np.ndarray]) -> None:
        """Every learning agent's envs one step; its transitions into the device memory."""
        n_rows = 0
        for i, agent in enumerate(self.agents):
            if not agent.learning:
                continue
            a = actions[i]
            nobs, r, term, trunc, info = agent.env.step(a)
            agent.env_steps += agent.cfg.num_envs
            agent.ep_return += r
            done = term | trunc
            # NStepCollector's order for n = 1: the envs still flying, then those done
            order = np.concatenate([np.flatnonzero(~done), np.flatnonzero(done)])
            nxt = nobs.copy()
            if np.any(done):
                nxt[done] = info["final_obs"][done]
            disc = np.where(term, 0.0, agent.cfg.gamma)
            rows = _pack(agent.obs[order], a[order], r[order], nxt[order], disc[order])
            m = len(order)
            self.h_rows[n_rows : n_rows + m] = torch.from_numpy(rows)
            at = (agent.replay_pos + np.arange(m)) % self.capacity
            self.h_rows_at[n_rows : n_rows + m] = torch.from_numpy(
                i * self.region + self.demo_rows + at
            )
            n_rows += m
            agent.replay_pos = int((agent.replay_pos + m) % self.capacity)
            agent.replay_size = int(min(agent.replay_size + m, self.capacity))
            for e in np.flatnonzero(done):
                self._episode_row(agent, e, info)
            agent.obs = nobs
        if n_rows:
            rows = self.h_rows[:n_rows].to(self.device, non_blocking=True)
            at = self.h_rows_at[:n_rows].to(self.device, non_blocking=True)
            self.store.index_copy_(0, at, rows)

    def _episode_row(self, agent: AgentState, e: int, info: dict[str, Any]) -> None:
        agent.episodes += 1
        ok = bool(info["landed"][e])
        agent.successes += ok
        agent.logs.episodes.row(
            agent.episodes,
            self._now(),
            agent.env_steps,
            agent.updates,
            float(agent.ep_return[e]),
            int(ok),
            float(info["fuel_kg"][e]),
            float(info["final_state"][e][5]),
            agent.epsilon,
        )
        agent.recent.append((float(agent.ep_return[e]), int(ok)))
        agent.ep_return[e] = 0.0
        if self._bar is not None:
            self._bar.update(1)

    def owed(self) -> list[int]:
        """Updates each agent owes after its last step: K once its replay holds
        `learning_starts` transitions, fewer where `max_updates` stops it, 0 when done."""
        out = []
        for agent in self.agents:
            n = 0
            if agent.learning and agent.replay_size >= agent.cfg.learning_starts:
                n = self.k
                if agent.cfg.max_updates > 0:
                    n = max(0, min(n, agent.cfg.max_updates - agent.updates))
            out.append(n)
        return out

    def update_block(self, owed: list[int]) -> None:
        """The owed updates: one block of K for every agent, agents owing fewer masked."""
        if not any(owed):
            return
        done_before = max(ag.updates for ag, n in zip(self.agents, owed, strict=True) if n)
        j = np.arange(self.k)
        self.h_flags.numpy()[:] = (done_before + j + 1) % self.cfgs[0].target_period == 0
        learns = j[:, None] < np.asarray(owed)[None, :]
        self.h_scale.numpy()[:, :, 0] = np.where(learns, 2.0 / self.batch, 0.0)
        size, base = self._column_plan()
        self.h_plan[0] = torch.from_numpy(size)
        self.h_plan[1] = torch.from_numpy(size - 1.0)
        self.h_plan[2] = torch.from_numpy(base.astype(np.float64))
        plan = self.h_plan.to(self.device, non_blocking=True)
        self.size_col.copy_(plan[0])
        self.last_col.copy_(plan[1])
        self.base_col.copy_(plan[2])
        self.flags.copy_(self.h_flags, non_blocking=True)
        self.scale.copy_(self.h_scale, non_blocking=True)
        if self.host_indices:
            self._draw_host_indices(owed, base)
        else:
            torch.rand(self.u.shape, dtype=torch.float64, out=self.u, generator=self.gen)
        self._block()
        for agent, n in zip(self.agents, owed, strict=True):
            agent.updates += n

    def _draw_host_indices(self, owed: list[int], base: np.ndarray) -> None:
        """The reference loop's draws: per update, k replay rows then k_demo demonstration rows
        from the agent's numpy generator (`Trainer.sample`)."""
        self.h_idx.copy_(torch.from_numpy(base))
        for j in range(self.k):
            for i, agent in enumerate(self.agents):
                if j >= owed[i]:
                    continue
                held = {REPLAY: agent.replay_size, DEMO: agent.demo_size}
                ix = [agent.rng.integers(0, held[m], size=n) for m, n in self._plan(agent).parts]
                self.h_idx[j, i] = torch.from_numpy(np.concatenate(ix) + base[i])
        self.idx.copy_(self.h_idx)

    def iterate(self, pending: list[int]) -> list[int]:
        """One batched env step of every agent and the updates it owes: act, step, update
        (with `overlap`: act, the updates `pending` from the step before, step). Returns the
        updates still pending (with `overlap`, this step's)."""
        actions = self.act()
        if self.overlap:
            self.update_block(pending)  # the GPU works while the CPU steps the envs
        self.step(actions)
        owed = self.owed()
        if self.overlap:
            return owed
        self.update_block(owed)
        return [0] * len(self.agents)

    # ---- the run
    def run(self) -> list[dict[str, Any]]:
        """Train until every agent reached its episodes (or max_updates), or the first
        agent's max_minutes; evaluations, logs and policy files as `Trainer.run`."""
        for agent in self.agents:
            meta = {**agent.cfg.to_dict(), "code_version": code_version()}
            meta["run"] = self.device_metadata()
            (agent.run_dir / "config.json").write_text(json.dumps(meta, indent=2) + "\n")
        total = sum(a.cfg.episodes for a in self.agents)
        show = self.cfgs[0].progress and not self.quiet
        self._bar = tqdm(total=total, unit="ep", smoothing=0.05) if show else None
        self._t0 = time.perf_counter() - self.wall_s
        last_log, last_ckpt, pending = self._now(), self._now(), self.pending
        stop = ""
        while not (stop := self._stop_reason()):
            pending = self.iterate(pending)
            self._retire(pending)
            t = self._now()
            if t - last_ckpt >= self.cfgs[0].checkpoint_every_s:
                last_ckpt = t
                self.checkpoint(pending)
            if t - last_log >= METRICS_PERIOD_S:
                last_log = t
                self._log_metrics(t)
            for agent in self.agents:
                if self._eval_due(agent, t):
                    self._evaluate(agent)
        self.update_block(pending)
        self.pending = [0] * len(self.agents)
        self.wall_s = self._now()
        out = [self._finish(agent, stop) for agent in self.agents]
        self.checkpoint(self.pending)
        if self._bar is not None:
            self._bar.close()
        return out

    def checkpoint(self, pending: list[int]) -> Path:
        """`home`/checkpoint.pt: the whole loop after its last step (`pd-train --resume`)."""
        return write_checkpoint(self.home, loop_state(self, pending))

    @classmethod
    def resume(cls, path: str | Path, overrides: dict[str, Any] | None = None) -> DeviceLoop:
        """The loop of a device-loop checkpoint (its folder or file), with config `overrides`
        (a later `max_minutes` or `episodes`, another `device`), ready to `run` on."""
        ckpt, state, cfgs, run_dirs = read_loop_checkpoint(path, overrides)
        loop = cls(cfgs, run_dirs, home=ckpt.parent)
        loop.pending = restore(loop, state)
        return loop

    def _retire(self, pending: list[int]) -> None:
        """An agent that reached its episodes or max_updates stops learning (after the updates
        its last step owes)."""
        for agent, n in zip(self.agents, pending, strict=True):
            cfg = agent.cfg
            reached = agent.episodes >= cfg.episodes or (
                cfg.max_updates > 0 and agent.updates + n >= cfg.max_updates
            )
            if agent.learning and reached:
                agent.learning = False

    def _stop_reason(self) -> str:
        cfg = self.cfgs[0]
        if cfg.max_minutes > 0 and self._now() >= 60.0 * cfg.max_minutes:
            return "max_minutes"
        if not any(a.learning for a in self.agents):
            return "episodes or max_updates"
        return ""

    def _eval_due(self, agent: AgentState, t: float) -> bool:
        cfg = agent.cfg
        if not agent.learning:
            return False
        if cfg.eval_every_updates > 0:
            return agent.updates - max(agent.last_eval_updates, 0) >= cfg.eval_every_updates
        return cfg.eval_every_s > 0 and t - agent.last_eval_s >= cfg.eval_every_s

    def _evaluate(self, agent: AgentState) -> None:
        i = self.agents.index(agent)
        ev = greedy_evaluation(self.q.network(i), agent.cfg)
        t = self._now()
        agent.last_eval_s, agent.last_eval_updates = t, agent.updates
        agent.logs.evals.row(t, agent.updates, agent.episodes, *ev.values())
        agent.logs.evals.flush()
        key = (ev["success_rate"], -ev["fuel_median"])
        if key > agent.best_eval:
            agent.best_eval = key
            self._save(agent, "best", {"periodic_eval": ev})

    def _log_metrics(self, t: float) -> None:
        diff = self.last_diff.cpu().numpy()
        for i, agent in enumerate(self.agents):
            ret = float(np.mean([x[0] for x in agent.recent])) if agent.recent else float("nan")
            suc = float(np.mean([x[1] for x in agent.recent])) if agent.recent else float("nan")
            loss = float(np.mean(diff[i] ** 2))
            eps = epsilon_at(agent.episodes, agent.cfg)
            nan = float("nan")
            row = (t, agent.env_steps, agent.updates, agent.episodes, eps, loss, loss, nan, nan)
            agent.logs.metrics.row(*row, ret, suc)
            agent.logs.flush()
        ups = sum(a.updates for a in self.agents) / max(t, 1e-9)
        if self._bar is not None:
            self._bar.set_postfix_str(f"{ups:,.0f} upd/s, agents x{len(self.agents)}")
        elif not self.quiet and t - self._last_print >= STATUS_PERIOD_S:
            self._last_print = t
            each = ", ".join(f"{a.episodes} ep {a.updates} upd" for a in self.agents)
            print(f"pd-train: {t:6.0f} s, {ups:,.0f} updates/s in all; {each}", flush=True)

    def _save(self, agent: AgentState, name: str, extra: dict[str, Any] | None = None) -> Path:
        i = self.agents.index(agent)
        meta = policy_metadata(
            agent.cfg,
            {
                "updates": agent.updates,
                "episodes": agent.episodes,
                "env_steps": agent.env_steps,
                "wall_s": self._now(),
                "demos": agent.demo_info,
                "device": self.device_metadata(),
                **(extra or {}),
            },
        )
        net = self.q.network(i)
        return save_policy(agent.run_dir / name, net, runtime_config_for(agent.cfg), meta)

    def _finish(self, agent: AgentState, stop: str) -> dict[str, Any]:
        on = agent.cfg.eval_every_updates > 0 or agent.cfg.eval_every_s > 0
        if on and agent.last_eval_updates != agent.updates:
            self._evaluate(agent)
        final = self._save(agent, "final")
        agent.logs.close()
        try:
            training_curves(agent.run_dir, agent.run_dir / "curves.png")
        except Exception as exc:  # noqa: BLE001 - plotting must never lose a trained model
            print(f"pd-train: could not plot curves: {exc}")
        return {
            "run_dir": str(agent.run_dir),
            "preset": agent.cfg.preset,
            "seed": agent.cfg.seed,
            "stop_reason": stop if agent.learning else "episodes or max_updates",
            "episodes": agent.episodes,
            "successes": agent.successes,
            "env_steps": agent.env_steps,
            "updates": agent.updates,
            "wall_s": self.wall_s,
            "device": describe_device(self.device),
            "final_policy": str(final),
            "best_eval": list(agent.best_eval),
        }

    def device_metadata(self) -> dict[str, Any]:
        return {
            "requested": self.cfgs[0].device,
            "used": describe_device(self.device),
            "loop": "device",
            "replay": "device",
            "cuda_graph": self.graph,
            "updates_per_graph": self.k,
            "agents_together": [f"{c.preset}:{c.seed}" for c in self.cfgs],
            "overlap": self.overlap,
            "torch": torch.__version__,
        }


def _pack(
    obs: np.ndarray,
    actions: np.ndarray,
    rewards: np.ndarray,
    next_obs: np.ndarray,
    discounts: np.ndarray,
) -> np.ndarray:
    """Transitions as (N, 17) float32 rows (values rounded to float32 as `ReplayMemory` stores
    them; an action index is exact in float32)."""
    n = len(actions)
    rows = np.empty((n, ROW), dtype=np.float32)
    rows[:, _OBS] = obs
    rows[:, _ACT] = actions
    rows[:, _REW] = rewards
    rows[:, _DISC] = discounts
    rows[:, _NEXT] = next_obs
    return rows
