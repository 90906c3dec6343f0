"""DQN agent with demonstrations (Sec. 2.3): online and target Q-networks, TD loss of Eq. 11.

Options beyond the paper, each off by default: double DQN, n-step targets (through the stored
discount), Huber loss, Adam, gradient clipping and DQfD's large-margin loss on demonstrations.
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from pd_core.dqn.config import TrainConfig
from pd_core.dqn.network import QNetwork
from pd_core.dqn.replay import ReplaySample


def epsilon_at(finished_episodes: int, cfg: TrainConfig) -> float:
    """Linear from epsilon0 to epsilon_final over epsilon_episodes finished episodes (Sec. 2.3)."""
    if cfg.epsilon_episodes <= 0:
        return cfg.epsilon_final
    frac = min(finished_episodes / cfg.epsilon_episodes, 1.0)
    return cfg.epsilon0 + frac * (cfg.epsilon_final - cfg.epsilon0)


def td_targets(
    target_net: QNetwork,
    online_net: QNetwork | None,
    rewards: torch.Tensor,
    next_obs: torch.Tensor,
    discounts: torch.Tensor,
) -> torch.Tensor:
    """r + discount * max_a Q_T(s', a) (Eq. 11; discount 0 for terminal s').

    With `online_net` given (double DQN), the action is argmax_a Q_online(s', a).
    """
    with torch.no_grad():
        q_next = target_net(next_obs)
        if online_net is None:
            v = q_next.max(dim=1).values
        else:
            a = online_net(next_obs).argmax(dim=1, keepdim=True)
            v = q_next.gather(1, a).squeeze(1)
        return rewards + discounts * v


def large_margin_loss(q: torch.Tensor, actions: torch.Tensor, margin: float) -> torch.Tensor:
    """DQfD: mean over rows of max_a [Q(s,a) + l(a_E,a)] - Q(s,a_E), l = margin for a != a_E."""
    lm = torch.full_like(q, margin)
    lm.scatter_(1, actions[:, None], 0.0)
    return ((q + lm).max(dim=1).values - q.gather(1, actions[:, None]).squeeze(1)).mean()


class DQNAgent:
    """Online network, target network and optimiser; `update` does one gradient step."""

    def __init__(self, cfg: TrainConfig, n_inputs: int = 7, n_actions: int = 147) -> None:
        self.cfg = cfg
        self.q = QNetwork(
            n_inputs, n_actions, tuple(cfg.hidden), cfg.activation, near_pad=cfg.near_pad
        )
        self.q_target = copy.deepcopy(self.q)
        for p in self.q_target.parameters():
            p.requires_grad_(False)
        if cfg.optimizer == "rmsprop":
            self.opt: torch.optim.Optimizer = torch.optim.RMSprop(self.q.parameters(), lr=cfg.lr)
        elif cfg.optimizer == "adam":
            self.opt = torch.optim.Adam(self.q.parameters(), lr=cfg.lr, eps=1.5e-4)
        else:
            raise ValueError(f"optimizer must be rmsprop or adam, got {cfg.optimizer!r}")
        if cfg.loss not in ("mse", "huber"):
            raise ValueError(f"loss must be mse or huber, got {cfg.loss!r}")
        self.updates = 0

    def init_input_normalisation(self, obs: np.ndarray) -> None:
        """First layer W x + b -> W (x - mu) / sigma + b, for both networks (same shape)."""
        x = self.q.inputs(torch.as_tensor(obs, dtype=torch.float32))
        mu, sigma = x.mean(0), x.std(0).clamp_min(1e-3)
        first = self.q.net[0]
        with torch.no_grad():
            w = first.weight / sigma
            first.bias.sub_(w @ mu)
            first.weight.copy_(w)
        self.sync_target()

    def act(self, obs: np.ndarray, epsilon: float, rng: np.random.Generator) -> np.ndarray:
        """Epsilon-greedy actions (B,) for scaled observations (B, 7)."""
        with torch.no_grad():
            greedy = self.q(torch.as_tensor(obs, dtype=torch.float32)).argmax(dim=1).numpy()
        if epsilon <= 0.0:
            return greedy
        explore = rng.random(len(greedy)) < epsilon
        rand = rng.integers(0, self.q.n_actions, size=len(greedy))
        return np.where(explore, rand, greedy)

    def loss(self, batch: ReplaySample) -> tuple[torch.Tensor, dict[str, float]]:
        cfg = self.cfg
        q_all = self.q(batch.obs)
        q = q_all.gather(1, batch.actions[:, None]).squeeze(1)
        target = td_targets(
            self.q_target,
            self.q if cfg.double_dqn else None,
            batch.rewards,
            batch.next_obs,
            batch.discounts,
        )
        if cfg.loss == "mse":
            td = F.mse_loss(q, target)
        else:
            td = F.smooth_l1_loss(q, target)
        total = td
        info = {"td_loss": float(td.detach())}
        if cfg.margin > 0.0 and bool(batch.demo.any()):
            d = batch.demo
            lm = large_margin_loss(q_all[d], batch.actions[d], cfg.margin_value)
            total = total + cfg.margin * lm
            info["margin_loss"] = float(lm.detach())
        info["loss"] = float(total.detach())
        info["q_mean"] = float(q.detach().mean())
        return total, info

    def update(self, batch: ReplaySample) -> dict[str, float]:
        """One gradient step; copies the target network every `target_period` updates."""
        loss, info = self.loss(batch)
        self.opt.zero_grad(set_to_none=True)
        loss.backward()
        if self.cfg.grad_clip > 0.0:
            torch.nn.utils.clip_grad_norm_(self.q.parameters(), self.cfg.grad_clip)
        self.opt.step()
        self.updates += 1
        if self.updates % self.cfg.target_period == 0:
            self.sync_target()
        return info

    def sync_target(self) -> None:
        self.q_target.load_state_dict(self.q.state_dict())

    def state_dict(self) -> dict[str, Any]:
        return {
            "q": self.q.state_dict(),
            "q_target": self.q_target.state_dict(),
            "opt": self.opt.state_dict(),
            "updates": self.updates,
        }

    def load_state_dict(self, d: dict[str, Any]) -> None:
        self.q.load_state_dict(d["q"])
        self.q_target.load_state_dict(d["q_target"])
        self.opt.load_state_dict(d["opt"])
        self.updates = int(d["updates"])


def concat_samples(a: ReplaySample, b: ReplaySample | None) -> ReplaySample:
    if b is None:
        return a
    return ReplaySample(*(torch.cat([x, y]) for x, y in zip(a, b, strict=True)))
