"""Training on the device the networks live on (`pd-train --device`), CPU included.

`DeviceReplay` is a replay memory held as torch tensors on a device; `DeviceUpdate` does one DQN
update from such memories: it draws the minibatch indices on the device (a torch Generator),
gathers the rows, forms the (double-)DQN target and the loss, and steps the optimiser, with no
value read back to the host. On cuda the whole step after the draw is one CUDA graph (static
index buffers, the optimiser made `capturable`), so an update is two launches and moves no batch
between host and GPU. Everything but the graph capture runs on the CPU too: the tests fly this
code path there and compare it with the numpy path of `pd_core.dqn.replay`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from pd_core.dqn.agent import DQNAgent
from pd_core.dqn.minibatch import DEMO, REPLAY, plan_of
from pd_core.dqn.replay import ReplayMemory

WARMUP_STEPS = 3
"""eager steps on a side stream before a CUDA graph is captured (they count as updates)"""


def resolve_device(name: str) -> torch.device:
    """`auto` -> cuda when torch sees one, else cpu; ValueError for cuda without one."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cuda" and not torch.cuda.is_available():
        raise ValueError(
            f"device cuda: torch {torch.__version__} sees no CUDA device (use --device cpu or auto)"
        )
    if name not in ("cpu", "cuda"):
        raise ValueError(f"device must be auto, cpu or cuda, got {name!r}")
    return torch.device(name)


def describe_device(device: torch.device) -> str:
    """`cpu`, or `cuda:0 (NVIDIA H100 80GB HBM3)`: what the run metadata records."""
    if device.type != "cuda":
        return device.type
    index = device.index if device.index is not None else torch.cuda.current_device()
    return f"cuda:{index} ({torch.cuda.get_device_name(index)})"


class DeviceReplay:
    """Fixed-capacity ring buffer of torch tensors on `device` (`ReplayMemory`'s layout and
    checkpoint format, so a run can resume across paths); rows are written in place, never
    reallocated, so a captured graph can keep reading them."""

    FIELDS = ("obs", "actions", "rewards", "next_obs", "discounts")

    def __init__(self, capacity: int, obs_dim: int = 7, device: torch.device | str = "cpu") -> None:
        if capacity < 1:
            raise ValueError(f"capacity must be >= 1, got {capacity}")
        dev = torch.device(device)
        self.capacity, self.obs_dim, self.device = capacity, obs_dim, dev
        self.obs = torch.zeros((capacity, obs_dim), dtype=torch.float32, device=dev)
        self.next_obs = torch.zeros((capacity, obs_dim), dtype=torch.float32, device=dev)
        self.actions = torch.zeros(capacity, dtype=torch.int64, device=dev)
        self.rewards = torch.zeros(capacity, dtype=torch.float32, device=dev)
        self.discounts = torch.zeros(capacity, dtype=torch.float32, device=dev)
        self.pos = 0
        self.size = 0
        # the size as the device sees it, for index draws inside a graph
        self.size_t = torch.zeros((), dtype=torch.float64, device=dev)
        self.last_t = torch.zeros((), dtype=torch.int64, device=dev)

    def __len__(self) -> int:
        return self.size

    @classmethod
    def from_memory(cls, mem: ReplayMemory, device: torch.device | str) -> DeviceReplay:
        """A device copy of a numpy memory (the demonstrations, read-only from then on)."""
        out = cls(mem.capacity, mem.obs.shape[1], device)
        out.load_state_dict(mem.state_dict())
        return out

    def _set_size(self, size: int, pos: int) -> None:
        self.size, self.pos = size, pos
        self.size_t.fill_(float(size))
        self.last_t.fill_(size - 1)

    def add(
        self,
        obs: np.ndarray,
        actions: np.ndarray,
        rewards: np.ndarray,
        next_obs: np.ndarray,
        discounts: np.ndarray,
    ) -> None:
        """Append a batch of transitions (leading axis B), as `ReplayMemory.add`."""
        obs = np.asarray(obs, dtype=np.float32).reshape(-1, self.obs_dim)
        b = obs.shape[0]
        if b == 0:
            return
        if b > self.capacity:  # keep only the newest
            sl = slice(b - self.capacity, b)
            return self.add(obs[sl], actions[sl], rewards[sl], next_obs[sl], discounts[sl])
        idx = torch.from_numpy((self.pos + np.arange(b)) % self.capacity).to(self.device)
        rows = (
            obs,
            np.asarray(actions, dtype=np.int64).reshape(b),
            np.asarray(rewards, dtype=np.float32).reshape(b),
            np.asarray(next_obs, dtype=np.float32).reshape(b, -1),
            np.asarray(discounts, dtype=np.float32).reshape(b),
        )
        for name, arr in zip(self.FIELDS, rows, strict=True):
            getattr(self, name).index_copy_(0, idx, torch.from_numpy(arr).to(self.device))
        self._set_size(int(min(self.size + b, self.capacity)), int((self.pos + b) % self.capacity))

    def rows(self, idx: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """(obs, actions, rewards, next_obs, discounts) at `idx` (on the device)."""
        return tuple(getattr(self, k).index_select(0, idx) for k in self.FIELDS)

    def state_dict(self) -> dict[str, Any]:
        """`ReplayMemory.state_dict`'s format, on the CPU."""
        n = self.size
        out: dict[str, Any] = {"capacity": self.capacity, "is_demo": False, "pos": self.pos}
        out["size"] = n
        for k in self.FIELDS:
            out[k] = getattr(self, k)[:n].cpu().clone()
        return out

    def load_state_dict(self, d: dict[str, Any]) -> None:
        if int(d["capacity"]) != self.capacity:
            raise ValueError(f"capacity differs: saved {d['capacity']}, now {self.capacity}")
        n = int(d["size"])
        for k in self.FIELDS:
            getattr(self, k)[:n].copy_(d[k])
        self._set_size(n, int(d["pos"]))


class _Plan:
    """The static buffers of one kind of update (pre-training on demonstrations only, or
    interaction: agent rows then demonstration rows) and its graph once captured."""

    def __init__(
        self, parts: list[tuple[DeviceReplay, int]], margin_from: int | None, dev: torch.device
    ) -> None:
        total = sum(k for _, k in parts)
        self.u = torch.zeros(total, dtype=torch.float64, device=dev)
        self.parts: list[tuple[DeviceReplay, torch.Tensor, slice]] = []
        start = 0
        for mem, k in parts:
            idx = torch.zeros(k, dtype=torch.int64, device=dev)
            self.parts.append((mem, idx, slice(start, start + k)))
            start += k
        self.margin_rows = None if margin_from is None else slice(margin_from, None)
        self.graph: Any = None
        self.out: dict[str, torch.Tensor] = {}
        self.warm = 0


class DeviceUpdate:
    """One DQN update per call from device memories (`replay`, `demo`), as `DQNAgent.update`
    on `Trainer.sample`'s minibatch: `batch_agent` agent rows then `batch_demo` demonstration
    rows (pre-training: all from the demonstrations), the large-margin loss on the latter.

    Indices: uniform over each memory's current size, from `generator` on the device (the draw
    is one launch before the step); or, with `index_rng` (a numpy Generator), drawn on the host
    exactly as the numpy path draws them, which makes this path's minibatches those of the
    numpy path (the tests' comparison). `graph=True` (cuda only) captures the step after
    `WARMUP_STEPS` eager ones and replays it from then on; a captured step keeps the learning
    rate it was captured with, so `reset()` after changing the optimiser's param groups.
    Returns the loss parts as device tensors (read them only when logging: that syncs).
    """

    def __init__(
        self,
        agent: DQNAgent,
        replay: DeviceReplay,
        demo: DeviceReplay | None,
        generator: torch.Generator | None = None,
        graph: bool = False,
        index_rng: np.random.Generator | None = None,
    ) -> None:
        if graph and agent.device.type != "cuda":
            raise ValueError(f"a CUDA graph needs the agent on cuda, not {agent.device}")
        if graph and not agent.capturable:
            raise ValueError("a CUDA graph needs the agent's optimiser made capturable")
        if generator is None and index_rng is None:
            raise ValueError("DeviceUpdate needs a torch generator or a numpy index_rng")
        self.agent, self.replay, self.demo = agent, replay, demo
        self.gen, self.graph, self.index_rng = generator, graph, index_rng
        self._plans: dict[bool, _Plan] = {}

    def reset(self) -> None:
        """Forget the captured graphs (and buffers): the next calls warm up and capture anew."""
        self._plans.clear()

    def _plan(self, pretraining: bool) -> _Plan:
        plan = self._plans.get(pretraining)
        if plan is not None:
            return plan
        cfg = self.agent.cfg
        rows = plan_of(cfg, has_demo=self.demo is not None, pretraining=pretraining)
        if not pretraining:
            self._plans.pop(True, None)  # pre-training is over: free its graph
        memories = {REPLAY: self.replay, DEMO: self.demo}
        parts = [(memories[m], n) for m, n in rows.parts]
        plan = self._plans[pretraining] = _Plan(parts, rows.margin_from, self.agent.device)
        return plan

    def _draw(self, plan: _Plan) -> None:
        """The indices' random numbers (device), or the indices themselves (numpy, host)."""
        if self.index_rng is None:
            torch.rand(plan.u.shape, generator=self.gen, dtype=torch.float64, out=plan.u)
            return
        for mem, idx, _ in plan.parts:
            if mem.size == 0:
                raise ValueError("cannot sample from an empty replay memory")
            idx.copy_(torch.from_numpy(self.index_rng.integers(0, mem.size, size=len(idx))))

    def _step(self, plan: _Plan) -> dict[str, torch.Tensor]:
        """The captured part: indices from the uniforms, rows, loss, backward, optimiser step."""
        if self.index_rng is None:
            for mem, idx, sl in plan.parts:
                torch.minimum((plan.u[sl] * mem.size_t).long(), mem.last_t, out=idx)
        cols = list(zip(*(mem.rows(idx) for mem, idx, _ in plan.parts), strict=True))
        batch = [c[0] if len(c) == 1 else torch.cat(c) for c in cols]
        terms = self.agent.loss_terms(*batch, demo_rows=plan.margin_rows)
        self.agent.gradient_step(terms["loss"])
        return {k: v.detach() for k, v in terms.items()}

    def __call__(self, pretraining: bool = False) -> dict[str, torch.Tensor]:
        plan = self._plan(pretraining)
        if self.index_rng is None and any(mem.size == 0 for mem, _, _ in plan.parts):
            raise ValueError("cannot sample from an empty replay memory")
        self._draw(plan)
        if not self.graph:
            out = self._step(plan)
        elif plan.graph is not None:
            plan.graph.replay()
            out = plan.out
        elif plan.warm < WARMUP_STEPS:
            side = torch.cuda.Stream()
            side.wait_stream(torch.cuda.current_stream())
            with torch.cuda.stream(side):
                out = self._step(plan)
            torch.cuda.current_stream().wait_stream(side)
            plan.warm += 1
        else:
            plan.graph = torch.cuda.CUDAGraph()
            with torch.cuda.graph(plan.graph):
                plan.out = self._step(plan)
            plan.graph.replay()  # capture records the work, it does not run it
            out = plan.out
        self.agent.count_update()
        return out
