"""The run loop of `pd_core.dqn.train.Trainer`: pre-training on demonstrations, interaction,
periodic evaluation, checkpoints, logs and curves, until a stop criterion.

`TrainingLoop` is a base class of `Trainer` and uses the state `Trainer.__init__` builds (config,
agent, envs, memories, counters, logs); it holds no state of its own.
"""

from __future__ import annotations

import json
import time
from typing import Any

import numpy as np
from tqdm import tqdm

from pd_core.dqn.agent import epsilon_at
from pd_core.dqn.device import describe_device
from pd_core.dqn.run_log import CsvLog, RunLogs
from pd_core.plots import training_curves
from pd_core.runtime.policy_file import code_version

METRICS_PERIOD_S = 10.0
"""metrics.csv rows, log flushes and progress-bar updates this often"""
PRETRAIN_LOG_EVERY = 1000
"""pre-training updates between metrics rows (and eval/checkpoint checks)"""


class TrainingLoop:
    """`run` and its steps; see the module docstring."""

    def run(self) -> dict[str, Any]:
        """Pre-train on demonstrations (DQfD), then interact until a stop criterion."""
        cfg = self.cfg
        (self.run_dir / "config.json").write_text(
            json.dumps(
                {**cfg.to_dict(), "code_version": code_version(), "run": self.device_metadata()},
                indent=2,
            )
            + "\n"
        )
        logs = RunLogs(self.run_dir)
        bar = self._progress_bar()
        self._t0 = time.perf_counter() - self.c.wall_s
        self._pretrain(logs, bar)
        if cfg.lr_finetune > 0 and self.pretrained >= cfg.pretrain_updates:
            for group in self.agent.opt.param_groups:
                group["lr"] = cfg.lr_finetune
            if self._device_update is not None:
                self._device_update.reset()  # a captured step keeps the lr it was captured with
        last_log = self._now()
        while not (stop_reason := self._stop_reason()):
            eps = epsilon_at(self.c.episodes, cfg)
            self._env_step(eps, logs, bar)
            if len(self.replay) >= cfg.learning_starts:
                self.c.update_credit += cfg.updates_per_step
                # the updates of a batched step run together after it (updates_per_step =
                # num_envs: one per env transition); max_updates stops them on the exact count
                while self.c.update_credit >= 1.0 and not self._updates_done():
                    self.last_info = self.update()
                    self.c.update_credit -= 1.0
            t = self._now()
            if t - last_log >= METRICS_PERIOD_S:
                last_log = t
                self._log_metrics(logs, bar, t, eps)
            self._eval_and_checkpoint(logs, t)
        self.c.wall_s = self._now()
        if self.outcomes is not None:
            self._log_scenarios(self.c.wall_s)
        if self._unevaluated():
            self._periodic_eval(logs)
        final = self.save_policies("final")
        self.checkpoint()
        logs.close()
        if self._scenario_log is not None:
            self._scenario_log.close()
        if bar is not None:
            bar.close()
        self._plot_curves()
        return {
            "run_dir": str(self.run_dir),
            "stop_reason": stop_reason,
            "episodes": self.c.episodes,
            "successes": self.c.successes,
            "env_steps": self.c.env_steps,
            "updates": self.agent.updates,
            "wall_s": self.c.wall_s,
            "device": describe_device(self.device),
            "final_policy": str(final),
            "best_eval": list(self.c.best_eval),
        }

    def _now(self) -> float:
        """Wall seconds of the run, summed over resumed segments."""
        return time.perf_counter() - self._t0

    def _progress_bar(self) -> Any:
        if not self.cfg.progress or self.quiet:
            return None
        if self.cfg.dagger_rounds:  # no interaction: the bar counts the pre-training updates
            total, done, unit = self._pretrain_total(), self.pretrained, "upd"
        else:
            total, done, unit = self.cfg.episodes, self.c.episodes, "ep"
        return tqdm(total=total, initial=done, unit=unit, smoothing=0.05)

    def _stop_reason(self) -> str:
        cfg = self.cfg
        if self.c.episodes >= cfg.episodes:
            return "episodes"
        if cfg.max_minutes > 0 and self._now() >= 60.0 * cfg.max_minutes:
            return "max_minutes"
        if self._updates_done():
            return "max_updates"
        if cfg.dagger_rounds and self.pretrained >= self._pretrain_total():
            return "dagger_rounds"
        return ""

    def _pretrain_total(self) -> int:
        """Pre-training updates of the run: `pretrain_updates` before each DAgger round and
        after the last one."""
        return self.cfg.pretrain_updates * (1 + self.cfg.dagger_rounds)

    def _updates_done(self) -> bool:
        return 0 < self.cfg.max_updates <= self.agent.updates

    def _pretrain(self, logs: RunLogs, bar: Any) -> None:
        """DQfD pre-training: gradient updates on demonstrations only, before any interaction;
        with `dagger_rounds`, a round of labels every `pretrain_updates` updates (after an
        evaluation of the network about to be labelled)."""
        nan = float("nan")
        cfg = self.cfg
        while (
            self.demo is not None
            and self.pretrained < self._pretrain_total()
            and not self._stop_reason()  # --max-minutes / --max-updates bound pre-training too
        ):
            if self.dagger_round < min(self.pretrained // cfg.pretrain_updates, cfg.dagger_rounds):
                if self._unevaluated():
                    self._periodic_eval(logs)
                info = self.dagger_round_labels()
                self.c.wall_s = self._now()
                self.c.last_ckpt_s = self.c.wall_s
                self.checkpoint()  # a resumed run does not label this round again
                if not self.quiet:
                    (bar.write if bar is not None else print)(
                        f"pd-train: DAgger round {info['round']}: {info['labels']} labels "
                        f"(agreement {info['agreement']:.1%}, student landed "
                        f"{info['student_success_rate']:.1%}), {len(self.demo)} demonstrations"
                    )
                continue
            self.last_info = self.update(pretraining=True)
            self.pretrained += 1
            if self.pretrained % PRETRAIN_LOG_EVERY:
                continue
            self.c.wall_s = self._now()
            logs.metrics.row(
                self.c.wall_s, 0, self.agent.updates, 0, 1.0, *self._loss_row(), nan, nan
            )
            logs.metrics.flush()
            if bar is not None:
                if cfg.dagger_rounds:
                    bar.update(PRETRAIN_LOG_EVERY)
                    bar.set_postfix_str(f"DAgger rounds {self.dagger_round}/{cfg.dagger_rounds}")
                else:
                    bar.set_postfix_str(f"pretrain {self.pretrained}/{self._pretrain_total()}")
            self._eval_and_checkpoint(logs, self._now())

    def _env_step(self, eps: float, logs: RunLogs, bar: Any) -> None:
        """One batched epsilon-greedy step: n-step transitions into the replay, episode rows."""
        cfg = self.cfg
        actions = self.agent.act(self.obs, eps, self.rng)
        nobs, r, term, trunc, info = self.env.step(actions)
        self.c.env_steps += cfg.num_envs
        self.ep_return += r
        tr = self.collector.step(self.obs, actions, r, nobs, term, trunc, info.get("final_obs"))
        self.replay.add(*tr)
        for i in np.flatnonzero(term | trunc):
            self.c.episodes += 1
            ok = bool(info["landed"][i])
            self.c.successes += ok
            logs.episodes.row(
                self.c.episodes,
                self._now(),
                self.c.env_steps,
                self.agent.updates,
                float(self.ep_return[i]),
                int(ok),
                float(info["fuel_kg"][i]),
                float(info["final_state"][i][5]),
                eps,
            )
            self.recent.append((float(self.ep_return[i]), int(ok)))
            self.ep_return[i] = 0.0
            if self.outcomes is not None:
                self.outcomes.record(int(info["scenario"][i]), ok)
            if bar is not None:
                bar.update(1)
        if self.outcomes is not None and np.any(term | trunc):
            self.env.set_scenario_probs(self.outcomes.probs())
        self.obs = nobs

    def _log_metrics(self, logs: RunLogs, bar: Any, t: float, eps: float) -> None:
        self.c.wall_s = t
        ret = float(np.mean([x[0] for x in self.recent])) if self.recent else float("nan")
        suc = float(np.mean([x[1] for x in self.recent])) if self.recent else float("nan")
        logs.metrics.row(
            t,
            self.c.env_steps,
            self.agent.updates,
            self.c.episodes,
            eps,
            *self._loss_row(),
            ret,
            suc,
        )
        logs.flush()
        if self.outcomes is not None:
            self._log_scenarios(t)
        if bar is not None:
            bar.set_postfix_str(
                f"eps {eps:.3f} succ100 {suc:.2f} loss {float(self.last_info.get('loss', 0)):.3g}"
                f" upd {self.agent.updates}"
            )

    def _log_scenarios(self, t: float) -> None:
        """scenarios.csv: each scenario's draw probability and recent training failure rate."""
        assert self.outcomes is not None
        if self._scenario_log is None:
            names = [d.name for d in self.env.scenarios]
            head = ("wall_s", "episodes", *(f"p_{n}" for n in names), *(f"fail_{n}" for n in names))
            self._scenario_log = CsvLog(self.run_dir / "scenarios.csv", head)
        self._scenario_log.row(
            t, self.c.episodes, *map(float, self.outcomes.probs()),
            *map(float, self.outcomes.failure_rates()),
        )  # fmt: skip
        self._scenario_log.flush()

    def _eval_and_checkpoint(self, logs: RunLogs, t: float) -> None:
        """The periodic work shared by pre-training and interaction: evaluate, then checkpoint."""
        if self._eval_due(t):
            self._periodic_eval(logs)
        if t - self.c.last_ckpt_s >= self.cfg.checkpoint_every_s:
            self.c.wall_s = t
            self.c.last_ckpt_s = t
            self.checkpoint()

    def _unevaluated(self) -> bool:
        """Evaluations are on and the current network has not been evaluated yet."""
        on = self.cfg.eval_every_updates > 0 or self.cfg.eval_every_s > 0
        return on and self.c.last_eval_updates != self.agent.updates

    def _eval_due(self, t: float) -> bool:
        """A periodic evaluation is due: by gradient updates (`eval_every_updates`) or else by
        wall time (`eval_every_s`)."""
        cfg = self.cfg
        if cfg.eval_every_updates > 0:
            return self.agent.updates - max(self.c.last_eval_updates, 0) >= cfg.eval_every_updates
        return cfg.eval_every_s > 0 and t - self.c.last_eval_s >= cfg.eval_every_s

    def _loss_row(self) -> list[float]:
        li = self.last_info  # device tensors on the device path: read back here only
        keys = ("loss", "td_loss", "margin_loss", "q_mean")
        return [float(li.get(k, float("nan"))) for k in keys]

    def _periodic_eval(self, logs: RunLogs) -> None:
        ev = self.evaluate()
        t = self._now()
        self.c.last_eval_s = t
        self.c.last_eval_updates = self.agent.updates
        self.c.wall_s = t
        logs.evals.row(t, self.agent.updates, self.c.episodes, *ev.values())
        logs.evals.flush()
        key = (ev["success_rate"], -ev["fuel_median"])
        if key > tuple(self.c.best_eval):
            self.c.best_eval = key
            self.save_policies("best", {"periodic_eval": ev})
        if self.on_eval is not None:
            self.on_eval(
                {**ev, "wall_s": t, "updates": self.agent.updates, "episodes": self.c.episodes}
            )

    def _plot_curves(self) -> None:
        try:
            training_curves(self.run_dir, self.run_dir / "curves.png")
        except Exception as exc:  # noqa: BLE001 - plotting must never lose a trained model
            print(f"pd-train: could not plot curves: {exc}")
