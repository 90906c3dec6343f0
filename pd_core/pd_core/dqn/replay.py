"""Replay memories (Sec. 2.3): the agent's FIFO memory and a separate demonstration memory.

A stored transition is (obs, action, reward, next_obs, discount): obs are scaled states (Eq. 20),
reward is the (n-step) discounted sum, and discount is the factor on max_a Q_T(next_obs, a) in the
target: 0 when the episode terminated inside the n steps (Eq. 11, first case), gamma^k otherwise
(k steps taken; a time-limit truncation is not terminal, so it bootstraps).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
import torch


class ReplaySample(NamedTuple):
    """A minibatch; `demo` marks demonstration rows (for the large-margin loss)."""

    obs: torch.Tensor  # (B, 7) float32
    actions: torch.Tensor  # (B,) int64
    rewards: torch.Tensor  # (B,) float32
    next_obs: torch.Tensor  # (B, 7) float32
    discounts: torch.Tensor  # (B,) float32
    demo: torch.Tensor  # (B,) bool


class ReplayMemory:
    """Fixed-capacity ring buffer, uniform sampling; oldest transitions are overwritten first."""

    def __init__(self, capacity: int, obs_dim: int = 7, is_demo: bool = False) -> None:
        if capacity < 1:
            raise ValueError(f"capacity must be >= 1, got {capacity}")
        self.capacity = capacity
        self.is_demo = is_demo
        self.obs = np.zeros((capacity, obs_dim), dtype=np.float32)
        self.next_obs = np.zeros((capacity, obs_dim), dtype=np.float32)
        self.actions = np.zeros(capacity, dtype=np.int64)
        self.rewards = np.zeros(capacity, dtype=np.float32)
        self.discounts = np.zeros(capacity, dtype=np.float32)
        self.pos = 0
        self.size = 0

    def __len__(self) -> int:
        return self.size

    def add(
        self,
        obs: np.ndarray,
        actions: np.ndarray,
        rewards: np.ndarray,
        next_obs: np.ndarray,
        discounts: np.ndarray,
    ) -> None:
        """Append a batch of transitions (leading axis B)."""
        obs = np.asarray(obs, dtype=np.float32).reshape(-1, self.obs.shape[1])
        b = obs.shape[0]
        if b == 0:
            return
        if b > self.capacity:  # keep only the newest
            sl = slice(b - self.capacity, b)
            return self.add(obs[sl], actions[sl], rewards[sl], next_obs[sl], discounts[sl])
        idx = (self.pos + np.arange(b)) % self.capacity
        self.obs[idx] = obs
        self.actions[idx] = np.asarray(actions, dtype=np.int64).reshape(b)
        self.rewards[idx] = np.asarray(rewards, dtype=np.float32).reshape(b)
        self.next_obs[idx] = np.asarray(next_obs, dtype=np.float32).reshape(b, -1)
        self.discounts[idx] = np.asarray(discounts, dtype=np.float32).reshape(b)
        self.pos = int((self.pos + b) % self.capacity)
        self.size = int(min(self.size + b, self.capacity))

    def sample_indices(self, batch: int, rng: np.random.Generator) -> np.ndarray:
        if self.size == 0:
            raise ValueError("cannot sample from an empty replay memory")
        return rng.integers(0, self.size, size=batch)

    def get(self, idx: np.ndarray) -> ReplaySample:
        return ReplaySample(
            torch.from_numpy(self.obs[idx]),
            torch.from_numpy(self.actions[idx]),
            torch.from_numpy(self.rewards[idx]),
            torch.from_numpy(self.next_obs[idx]),
            torch.from_numpy(self.discounts[idx]),
            torch.full((len(idx),), self.is_demo, dtype=torch.bool),
        )

    def sample(self, batch: int, rng: np.random.Generator) -> ReplaySample:
        return self.get(self.sample_indices(batch, rng))

    def state_dict(self) -> dict[str, Any]:
        n = self.size
        return {
            "capacity": self.capacity,
            "is_demo": self.is_demo,
            "pos": self.pos,
            "size": n,
            "obs": torch.from_numpy(self.obs[:n].copy()),
            "next_obs": torch.from_numpy(self.next_obs[:n].copy()),
            "actions": torch.from_numpy(self.actions[:n].copy()),
            "rewards": torch.from_numpy(self.rewards[:n].copy()),
            "discounts": torch.from_numpy(self.discounts[:n].copy()),
        }

    def load_state_dict(self, d: dict[str, Any]) -> None:
        if int(d["capacity"]) != self.capacity:
            raise ValueError(f"capacity differs: saved {d['capacity']}, now {self.capacity}")
        n = int(d["size"])
        for k in ("obs", "next_obs", "actions", "rewards", "discounts"):
            getattr(self, k)[:n] = d[k].numpy()
        self.size, self.pos = n, int(d["pos"])


class DemoMemory(ReplayMemory):
    """The demonstration memory: filled once by `fill`, never overwritten (Sec. 2.3)."""

    def __init__(self, capacity: int, obs_dim: int = 7) -> None:
        super().__init__(capacity, obs_dim, is_demo=True)
        self._sealed = False

    def add(self, *args: Any, **kwargs: Any) -> None:
        if self._sealed:
            raise RuntimeError("the demonstration memory is never overwritten (Sec. 2.3)")
        super().add(*args, **kwargs)

    def seal(self) -> None:
        self._sealed = True

    @classmethod
    def fill(
        cls,
        obs: np.ndarray,
        actions: np.ndarray,
        rewards: np.ndarray,
        next_obs: np.ndarray,
        discounts: np.ndarray,
    ) -> DemoMemory:
        mem = cls(max(len(actions), 1), np.asarray(obs).shape[-1])
        mem.add(obs, actions, rewards, next_obs, discounts)
        mem.seal()
        return mem

    def extended(self, *columns: np.ndarray) -> DemoMemory:
        """A new sealed memory holding every transition of this one, then the transitions of
        `columns` (obs, actions, rewards, next_obs, discounts; DAgger's aggregation:
        demonstrations are added, never replaced)."""
        n = len(self)
        old = (self.obs, self.actions, self.rewards, self.next_obs, self.discounts)
        return DemoMemory.fill(
            *(np.concatenate([a[:n], np.asarray(c)]) for a, c in zip(old, columns, strict=True))
        )

    def load_state_dict(self, d: dict[str, Any]) -> None:
        self.__init__(int(d["capacity"]), d["obs"].shape[1])  # type: ignore[misc]
        super().load_state_dict(d)
        self.seal()


def nstep_from_episodes(
    obs: np.ndarray,
    actions: np.ndarray,
    rewards: np.ndarray,
    next_obs: np.ndarray,
    terminated: np.ndarray,
    episode: np.ndarray,
    gamma: float,
    n: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """n-step transitions from consecutive 1-step transitions grouped by `episode`.

    Rows of one episode must be contiguous and in time order. The last row of an episode that
    did not terminate is treated as a truncation (bootstrapped).
    Returns (obs, actions, n-step rewards, next_obs after k <= n steps, discounts).
    """
    m = len(actions)
    out_r = np.zeros(m)
    out_next = np.zeros_like(next_obs)
    out_disc = np.zeros(m)
    ep = np.asarray(episode)
    for i in range(m):
        g, k = 0.0, 0
        j = i
        while True:
            g += gamma**k * float(rewards[j])
            k += 1
            if terminated[j]:
                disc = 0.0
                break
            last = j + 1 >= m or ep[j + 1] != ep[i]
            if k == n or last:
                disc = gamma**k
                break
            j += 1
        out_r[i], out_next[i], out_disc[i] = g, next_obs[j], disc
    return obs, actions, out_r, out_next, out_disc


class NStepCollector:
    """Turns batched env steps into n-step transitions, per env, with truncation handled."""

    STATE = ("obs", "act", "rew", "count")
    """the arrays a checkpoint must keep to continue the open windows"""

    def __init__(self, num_envs: int, n: int, gamma: float, obs_dim: int = 7) -> None:
        self.n, self.gamma, self.num_envs = n, gamma, num_envs
        self.obs = np.zeros((num_envs, n, obs_dim), dtype=np.float32)
        self.act = np.zeros((num_envs, n), dtype=np.int64)
        self.rew = np.zeros((num_envs, n), dtype=np.float64)
        self.count = np.zeros(num_envs, dtype=np.int64)
        self._pows = gamma ** np.arange(n)

    def step(
        self,
        obs: np.ndarray,
        actions: np.ndarray,
        rewards: np.ndarray,
        next_obs: np.ndarray,
        terminated: np.ndarray,
        truncated: np.ndarray,
        final_obs: np.ndarray | None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Record one step of every env; returns the transitions completed by it.

        next_obs is the post-reset observation for envs that are done; their true last
        observation is final_obs.
        """
        n = self.n
        c = self.count
        # shift windows that are full, then write at position min(count, n - 1)
        full = c >= n
        if np.any(full):
            self.obs[full] = np.roll(self.obs[full], -1, axis=1)
            self.act[full] = np.roll(self.act[full], -1, axis=1)
            self.rew[full] = np.roll(self.rew[full], -1, axis=1)
        pos = np.minimum(c, n - 1)
        ar = np.arange(self.num_envs)
        self.obs[ar, pos] = obs
        self.act[ar, pos] = actions
        self.rew[ar, pos] = rewards
        self.count = c + 1
        done = terminated | truncated
        outs: list[tuple[np.ndarray, ...]] = []
        # envs still flying with a full window emit their oldest step
        emit = (~done) & (self.count >= n)
        if np.any(emit):
            g = self.rew[emit] @ self._pows
            outs.append(
                (
                    self.obs[emit, 0],
                    self.act[emit, 0],
                    g,
                    next_obs[emit],
                    np.full(int(emit.sum()), self.gamma**n),
                )
            )
        for i in np.flatnonzero(done):
            length = int(min(self.count[i], n))
            last = final_obs[i] if final_obs is not None else next_obs[i]
            for j in range(length):
                k = length - j
                g = float(self.rew[i, j:length] @ self._pows[:k])
                d = 0.0 if terminated[i] else self.gamma**k
                outs.append(
                    (
                        self.obs[i, j][None],
                        self.act[i, j : j + 1],
                        np.array([g]),
                        last[None],
                        np.array([d]),
                    )
                )
            self.count[i] = 0
        if not outs:
            z = np.zeros((0, self.obs.shape[2]), dtype=np.float32)
            return z, np.zeros(0, np.int64), np.zeros(0), z, np.zeros(0)
        return tuple(np.concatenate([o[k] for o in outs]) for k in range(5))  # type: ignore[return-value]
