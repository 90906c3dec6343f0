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
    """Online network, target network and optimiser; `update` does one gradient step.

    `device` is where both networks and the optimiser state live; `capturable` makes the
    optimiser capturable in a CUDA graph (`pd_core.dqn.device.DeviceUpdate`, cuda only). The
    networks are initialised on the CPU and then moved, so a seed gives the same initial
    weights on every device.
    """

    def __init__(
        self,
        cfg: TrainConfig,
        n_inputs: int = 7,
        n_actions: int = 147,
        device: torch.device | str = "cpu",
        capturable: bool = False,
    ) -> None:
        self.cfg = cfg
        self.device = torch.device(device)
        self.capturable = capturable
        self.q = QNetwork(
            n_inputs,
            n_actions,
            tuple(cfg.hidden),
            cfg.activation,
            near_pad=cfg.near_pad,
            thrust_input=cfg.thrust_input,
        ).to(self.device)
        self.q_target = copy.deepcopy(self.q)
        for p in self.q_target.parameters():
            p.requires_grad_(False)
        # the Polyak average of the online weights (cfg.weight_average > 0), else none
        self.q_avg: QNetwork | None = None
        if cfg.weight_average > 0.0:
            self.q_avg = copy.deepcopy(self.q)
            for p in self.q_avg.parameters():
                p.requires_grad_(False)
        # the parameter lists, walked once here rather than by every update
        self._params = list(self.q.parameters())
        self._avg_params = list(self.q_avg.parameters()) if self.q_avg is not None else []
        # capturable only where asked; foreach (one call for all parameters, where the CPU
        # default loops in Python) flies the same arithmetic per tensor: the same bits
        extra: dict[str, Any] = {"foreach": True}
        if capturable:
            extra["capturable"] = True
        if cfg.optimizer == "rmsprop":
            self.opt: torch.optim.Optimizer = torch.optim.RMSprop(self._params, lr=cfg.lr, **extra)
        elif cfg.optimizer == "adam":
            self.opt = torch.optim.Adam(self._params, lr=cfg.lr, eps=1.5e-4, **extra)
        else:
            raise ValueError(f"optimizer must be rmsprop or adam, got {cfg.optimizer!r}")
        if cfg.loss not in ("mse", "huber"):
            raise ValueError(f"loss must be mse or huber, got {cfg.loss!r}")
        self.updates = 0

    def init_input_normalisation(self, obs: np.ndarray) -> None:
        """First layer W x + b -> W (x - mu) / sigma + b, for both networks (same shape)."""
        x = self.q.inputs(torch.as_tensor(obs, dtype=torch.float32, device=self.device))
        mu, sigma = x.mean(0), x.std(0).clamp_min(1e-3)
        first = self.q.net[0]
        with torch.no_grad():
            w = first.weight / sigma
            first.bias.sub_(w @ mu)
            first.weight.copy_(w)
        self.sync_target()
        self.reset_average()

    def act(self, obs: np.ndarray, epsilon: float, rng: np.random.Generator) -> np.ndarray:
        """Epsilon-greedy actions (B,) for scaled observations (B, 7)."""
        with torch.no_grad():
            x = torch.as_tensor(obs, dtype=torch.float32, device=self.device)
            greedy = self.q(x).argmax(dim=1).cpu().numpy()
        if epsilon <= 0.0:
            return greedy
        explore = rng.random(len(greedy)) < epsilon
        rand = rng.integers(0, self.q.n_actions, size=len(greedy))
        return np.where(explore, rand, greedy)

    def loss_terms(
        self,
        obs: torch.Tensor,
        actions: torch.Tensor,
        rewards: torch.Tensor,
        next_obs: torch.Tensor,
        discounts: torch.Tensor,
        demo_rows: torch.Tensor | slice | None,
    ) -> dict[str, torch.Tensor]:
        """The loss and its parts as tensors, without reading any back to the host (so a CUDA
        graph can hold it): td_loss, margin_loss (only with `demo_rows`, the rows the
        large-margin loss sees), loss (the one to minimise) and q_mean."""
        cfg = self.cfg
        q_all = self.q(obs)
        q = q_all.gather(1, actions[:, None]).squeeze(1)
        target = td_targets(
            self.q_target, self.q if cfg.double_dqn else None, rewards, next_obs, discounts
        )
        td = F.mse_loss(q, target) if cfg.loss == "mse" else F.smooth_l1_loss(q, target)
        out = {"td_loss": td}
        total = td
        if demo_rows is not None:
            lm = large_margin_loss(q_all[demo_rows], actions[demo_rows], cfg.margin_value)
            total = total + cfg.margin * lm
            out["margin_loss"] = lm
        out["loss"] = total
        out["q_mean"] = q.detach().mean()
        return out

    def loss(self, batch: ReplaySample) -> tuple[torch.Tensor, dict[str, float]]:
        margin = self.cfg.margin > 0.0 and bool(batch.demo.any())
        terms = self.loss_terms(
            batch.obs,
            batch.actions,
            batch.rewards,
            batch.next_obs,
            batch.discounts,
            batch.demo if margin else None,
        )
        return terms["loss"], {k: float(v.detach()) for k, v in terms.items()}

    def gradient_step(self, loss: torch.Tensor) -> None:
        """Backward and optimiser step (with the gradient clip), no host sync."""
        self.opt.zero_grad(set_to_none=True)
        loss.backward()
        if self.cfg.grad_clip > 0.0:
            torch.nn.utils.clip_grad_norm_(self._params, self.cfg.grad_clip)
        self.opt.step()

    def count_update(self) -> None:
        """Count one update; copies the target network every `target_period` updates."""
        self.updates += 1
        if self.updates % self.cfg.target_period == 0:
            self.sync_target()

    def update(self, batch: ReplaySample) -> dict[str, float]:
        """One gradient step; copies the target network every `target_period` updates."""
        loss, info = self.loss(batch)
        self.gradient_step(loss)
        self.count_update()
        return info

    def sync_target(self) -> None:
        self.q_target.load_state_dict(self.q.state_dict())

    @property
    def policy_net(self) -> QNetwork:
        """The network that flies: the averaged one where there is one, else the online one."""
        return self.q if self.q_avg is None else self.q_avg

    def reset_average(self) -> None:
        """Restart the average at the online network's weights (a new starting point)."""
        if self.q_avg is not None:
            self.q_avg.load_state_dict(self.q.state_dict())

    def average_step(self) -> None:
        """w_avg <- d w_avg + (1 - d) w for every parameter (d = cfg.weight_average), one
        `lerp_` per tensor in one call. Called once per gradient update; nothing without an
        average. (The network's one buffer, the near-pad gain, is a constant.)"""
        if self.q_avg is None:
            return
        with torch.no_grad():
            torch._foreach_lerp_(self._avg_params, self._params, 1.0 - self.cfg.weight_average)

    def state_dict(self) -> dict[str, Any]:
        return {
            "q": self.q.state_dict(),
            "q_target": self.q_target.state_dict(),
            "opt": self.opt.state_dict(),
            "updates": self.updates,
            **({"q_avg": self.q_avg.state_dict()} if self.q_avg is not None else {}),
        }

    def load_state_dict(self, d: dict[str, Any]) -> None:
        self.q.load_state_dict(d["q"])
        self.q_target.load_state_dict(d["q_target"])
        if self.q_avg is not None:
            self.q_avg.load_state_dict(d["q_avg"])
        self.opt.load_state_dict(d["opt"])
        self._own_optimiser_flags()
        self.updates = int(d["updates"])

    def _own_optimiser_flags(self) -> None:
        """A loaded optimiser state brings its saver's `capturable` (a CUDA-graph run's, or a CPU
        run's) and `foreach`: keep this agent's own, with each step count where that wants it
        (a capturable optimiser counts on the device, the others on the CPU)."""
        for group in self.opt.param_groups:
            group["capturable"] = self.capturable
            group["foreach"] = True  # saved up to 2f59083: None, the same bits
        where = self.device if self.capturable else torch.device("cpu")
        for st in self.opt.state.values():
            step = st.get("step")
            if isinstance(step, torch.Tensor) and step.device != where:
                st["step"] = step.to(where, torch.float32)


def concat_samples(a: ReplaySample, b: ReplaySample | None) -> ReplaySample:
    if b is None:
        return a
    return ReplaySample(*(torch.cat([x, y]) for x, y in zip(a, b, strict=True)))
