"""The run loop of a `pd_core.dqn.train.Trainer`: pre-training on demonstrations (with DAgger
rounds), interaction, periodic evaluation and checkpoints, until a stop criterion.

`TrainingLoop(trainer, callbacks).run()` changes only the trainer's state (its agent, memories,
counters and checkpoints); what a run reports goes through `Callback`s, called in their order
at fixed points of the loop: `on_start`, `on_pretrain` (every `PRETRAIN_LOG_EVERY` pre-training
updates), `on_dagger_round`, `on_episode` (each finished training episode), `on_metrics`
(every `METRICS_PERIOD_S`), `on_eval` (each periodic evaluation) and `on_end`. The run folder's
CSV logs (`RunFiles`), the progress bar (`ProgressBar`), curves.png (`CurvesPlot`) and a
sweep's reports (`EvalReport`) are such callbacks; none of them draws a random number, so the
callbacks of a run do not change what it trains.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

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
LOSS_KEYS = ("loss", "td_loss", "margin_loss", "q_mean")


class Episode(NamedTuple):
    """A finished training episode, as episodes.csv has it."""

    episode: int
    wall_s: float
    env_steps: int
    updates: int
    ret: float
    landed: int
    fuel_kg: float
    k_velocity_mps: float
    epsilon: float


class Callback:
    """One reporter of a training run; every hook does nothing unless overridden. `run` is the
    `Trainer` (read it, do not change it)."""

    def on_start(self, run: Any) -> None: ...

    def on_pretrain(self, run: Any, wall_s: float) -> None: ...

    def on_dagger_round(self, run: Any, info: dict[str, Any]) -> None: ...

    def on_episode(self, run: Any, episode: Episode) -> None: ...

    def on_metrics(self, run: Any, wall_s: float, epsilon: float) -> None: ...

    def on_eval(self, run: Any, ev: dict[str, float], wall_s: float) -> None: ...

    def on_end(self, run: Any, summary: dict[str, Any]) -> None: ...


def loss_row(info: dict[str, Any]) -> list[float]:
    """The loss parts of an update's info (device tensors are read back here only)."""
    return [float(info.get(k, float("nan"))) for k in LOSS_KEYS]


class RunFiles(Callback):
    """episodes.csv, metrics.csv, evals.csv and scenarios.csv of the run folder
    (`pd_core.dqn.run_log`)."""

    def __init__(self) -> None:
        self.logs: RunLogs | None = None
        self.scenarios: CsvLog | None = None

    def on_start(self, run: Any) -> None:
        self.logs = RunLogs(run.run_dir)

    def on_pretrain(self, run: Any, wall_s: float) -> None:
        nan = float("nan")
        assert self.logs is not None
        row = (wall_s, 0, run.agent.updates, 0, 1.0, *loss_row(run.last_info), nan, nan)
        self.logs.metrics.row(*row)
        self.logs.metrics.flush()

    def on_episode(self, run: Any, episode: Episode) -> None:
        assert self.logs is not None
        self.logs.episodes.row(*episode)

    def on_metrics(self, run: Any, wall_s: float, epsilon: float) -> None:
        assert self.logs is not None
        ret, suc = recent_means(run)
        c = run.c
        row = (
            wall_s,
            c.env_steps,
            run.agent.updates,
            c.episodes,
            epsilon,
            *loss_row(run.last_info),
        )
        self.logs.metrics.row(*row, ret, suc)
        self.logs.flush()
        self._scenario_row(run, wall_s)

    def on_eval(self, run: Any, ev: dict[str, float], wall_s: float) -> None:
        assert self.logs is not None
        self.logs.evals.row(wall_s, run.agent.updates, run.c.episodes, *ev.values())
        self.logs.evals.flush()

    def on_end(self, run: Any, summary: dict[str, Any]) -> None:
        self._scenario_row(run, summary["wall_s"])
        if self.logs is not None:
            self.logs.close()
        if self.scenarios is not None:
            self.scenarios.close()

    def _scenario_row(self, run: Any, wall_s: float) -> None:
        """scenarios.csv: each scenario's draw probability and recent training failure rate."""
        outcomes = run.outcomes
        if outcomes is None:
            return
        if self.scenarios is None:
            names = [d.name for d in run.env.scenarios]
            head = ("wall_s", "episodes", *(f"p_{n}" for n in names), *(f"fail_{n}" for n in names))
            self.scenarios = CsvLog(run.run_dir / "scenarios.csv", head)
        self.scenarios.row(
            wall_s, run.c.episodes, *map(float, outcomes.probs()),
            *map(float, outcomes.failure_rates()),
        )  # fmt: skip
        self.scenarios.flush()


def recent_means(run: Any) -> tuple[float, float]:
    """(return, success) over the last 100 training episodes (nan before the first)."""
    if not run.recent:
        return float("nan"), float("nan")
    return (
        float(np.mean([x[0] for x in run.recent])),
        float(np.mean([x[1] for x in run.recent])),
    )


class ProgressBar(Callback):
    """A tqdm bar over episodes (pre-training updates for a DAgger run), and one line per DAgger
    round (printed without a bar); nothing at all when `quiet`."""

    def __init__(self, quiet: bool) -> None:
        self.quiet = quiet
        self.bar: Any = None

    def on_start(self, run: Any) -> None:
        if not run.cfg.progress or self.quiet:
            return
        if run.cfg.dagger_rounds:  # no interaction: the bar counts the pre-training updates
            total, done, unit = run.pretrain_total(), run.pretrained, "upd"
        else:
            total, done, unit = run.cfg.episodes, run.c.episodes, "ep"
        self.bar = tqdm(total=total, initial=done, unit=unit, smoothing=0.05)

    def on_pretrain(self, run: Any, wall_s: float) -> None:
        if self.bar is None:
            return
        if run.cfg.dagger_rounds:
            self.bar.update(PRETRAIN_LOG_EVERY)
            self.bar.set_postfix_str(f"DAgger rounds {run.dagger_round}/{run.cfg.dagger_rounds}")
        else:
            self.bar.set_postfix_str(f"pretrain {run.pretrained}/{run.pretrain_total()}")

    def on_dagger_round(self, run: Any, info: dict[str, Any]) -> None:
        if self.quiet:
            return
        (self.bar.write if self.bar is not None else print)(
            f"pd-train: DAgger round {info['round']}: {info['labels']} labels "
            f"(agreement {info['agreement']:.1%}, student landed "
            f"{info['student_success_rate']:.1%}), {len(run.demo)} demonstrations"
        )

    def on_episode(self, run: Any, episode: Episode) -> None:
        if self.bar is not None:
            self.bar.update(1)

    def on_metrics(self, run: Any, wall_s: float, epsilon: float) -> None:
        if self.bar is not None:
            loss = float(run.last_info.get("loss", 0))
            self.bar.set_postfix_str(
                f"eps {epsilon:.3f} succ100 {recent_means(run)[1]:.2f} loss {loss:.3g}"
                f" upd {run.agent.updates}"
            )

    def on_end(self, run: Any, summary: dict[str, Any]) -> None:
        if self.bar is not None:
            self.bar.close()


class CurvesPlot(Callback):
    """curves.png of the run folder at the end (`pd_core.plots.training_curves`)."""

    def on_end(self, run: Any, summary: dict[str, Any]) -> None:
        try:
            training_curves(run.run_dir, run.run_dir / "curves.png")
        except Exception as exc:  # noqa: BLE001 - plotting must never lose a trained model
            print(f"pd-train: could not plot curves: {exc}")


class EvalReport(Callback):
    """Calls `report` with every periodic evaluation plus wall_s, updates and episodes (how a
    sweep reports to Ray Tune)."""

    def __init__(self, report: Callable[[dict[str, float]], None]) -> None:
        self.report = report

    def on_eval(self, run: Any, ev: dict[str, float], wall_s: float) -> None:
        self.report(
            {**ev, "wall_s": wall_s, "updates": run.agent.updates, "episodes": run.c.episodes}
        )


class TrainingLoop:
    """`run` of a trainer; see the module docstring."""

    def __init__(self, trainer: Any, callbacks: Sequence[Callback]) -> None:
        self.t = trainer
        self.callbacks = list(callbacks)
        self._t0 = time.perf_counter() - trainer.c.wall_s

    def emit(self, hook: str, *args: Any) -> None:
        for cb in self.callbacks:
            getattr(cb, hook)(self.t, *args)

    def run(self) -> dict[str, Any]:
        """Pre-train on demonstrations (DQfD), then interact until a stop criterion."""
        t, cfg = self.t, self.t.cfg
        (t.run_dir / "config.json").write_text(
            json.dumps(
                {**cfg.to_dict(), "code_version": code_version(), "run": t.device_metadata()},
                indent=2,
            )
            + "\n"
        )
        self.emit("on_start")
        self._t0 = time.perf_counter() - t.c.wall_s
        self._pretrain()
        if cfg.lr_finetune > 0 and t.pretrained >= cfg.pretrain_updates:
            t.finetune_lr()
        last_log = self.now()
        while not (stop_reason := self.stop_reason()):
            eps = epsilon_at(t.c.episodes, cfg)
            self._env_step(eps)
            if len(t.replay) >= cfg.learning_starts:
                t.c.update_credit += cfg.updates_per_step
                # the updates of a batched step run together after it (updates_per_step =
                # num_envs: one per env transition); max_updates stops them on the exact count
                while t.c.update_credit >= 1.0 and not t.updates_done():
                    t.last_info = t.update()
                    t.c.update_credit -= 1.0
            now = self.now()
            if now - last_log >= METRICS_PERIOD_S:
                last_log = now
                t.c.wall_s = now
                self.emit("on_metrics", now, eps)
            self._eval_and_checkpoint(now)
        t.c.wall_s = self.now()
        if self._unevaluated():
            self._periodic_eval()
        final = t.save_policies("final")
        t.checkpoint()
        summary = {
            "run_dir": str(t.run_dir),
            "stop_reason": stop_reason,
            "episodes": t.c.episodes,
            "successes": t.c.successes,
            "env_steps": t.c.env_steps,
            "updates": t.agent.updates,
            "wall_s": t.c.wall_s,
            "device": describe_device(t.device),
            "final_policy": str(final),
            "best_eval": list(t.c.best_eval),
        }
        self.emit("on_end", summary)
        return summary

    def now(self) -> float:
        """Wall seconds of the run, summed over resumed segments."""
        return time.perf_counter() - self._t0

    def stop_reason(self) -> str:
        t, cfg = self.t, self.t.cfg
        if t.c.episodes >= cfg.episodes:
            return "episodes"
        if cfg.max_minutes > 0 and self.now() >= 60.0 * cfg.max_minutes:
            return "max_minutes"
        if t.updates_done():
            return "max_updates"
        if cfg.dagger_rounds and t.pretrained >= t.pretrain_total():
            return "dagger_rounds"
        return ""

    def _pretrain(self) -> None:
        """DQfD pre-training: gradient updates on demonstrations only, before any interaction;
        with `dagger_rounds`, a round of labels every `pretrain_updates` updates (after an
        evaluation of the network about to be labelled)."""
        t, cfg = self.t, self.t.cfg
        while (
            t.demo is not None
            and t.pretrained < t.pretrain_total()
            and not self.stop_reason()  # --max-minutes / --max-updates bound pre-training too
        ):
            if t.dagger_round < min(t.pretrained // cfg.pretrain_updates, cfg.dagger_rounds):
                if self._unevaluated():
                    self._periodic_eval()
                info = t.dagger_round_labels()
                t.c.wall_s = self.now()
                t.c.last_ckpt_s = t.c.wall_s
                t.checkpoint()  # a resumed run does not label this round again
                self.emit("on_dagger_round", info)
                continue
            t.last_info = t.update(pretraining=True)
            t.pretrained += 1
            if t.pretrained % PRETRAIN_LOG_EVERY:
                continue
            t.c.wall_s = self.now()
            self.emit("on_pretrain", t.c.wall_s)
            self._eval_and_checkpoint(self.now())

    def _env_step(self, eps: float) -> None:
        """One batched epsilon-greedy step: n-step transitions into the replay, episode rows."""
        t = self.t
        actions = t.agent.act(t.obs, eps, t.rng)
        nobs, r, term, trunc, info = t.env.step(actions)
        t.c.env_steps += t.cfg.num_envs
        t.ep_return += r
        tr = t.collector.step(t.obs, actions, r, nobs, term, trunc, info.get("final_obs"))
        t.replay.add(*tr)
        for i in np.flatnonzero(term | trunc):
            t.c.episodes += 1
            ok = bool(info["landed"][i])
            t.c.successes += ok
            episode = Episode(
                t.c.episodes, self.now(), t.c.env_steps, t.agent.updates,
                float(t.ep_return[i]), int(ok), float(info["fuel_kg"][i]),
                float(info["final_state"][i][5]), eps,
            )  # fmt: skip
            self.emit("on_episode", episode)
            t.recent.append((float(t.ep_return[i]), int(ok)))
            t.ep_return[i] = 0.0
            if t.outcomes is not None:
                t.outcomes.record(int(info["scenario"][i]), ok)
        if t.outcomes is not None and np.any(term | trunc):
            t.env.set_scenario_probs(t.outcomes.probs())
        t.obs = nobs

    def _eval_and_checkpoint(self, now: float) -> None:
        """The periodic work shared by pre-training and interaction: evaluate, then checkpoint."""
        t = self.t
        if self._eval_due(now):
            self._periodic_eval()
        if now - t.c.last_ckpt_s >= t.cfg.checkpoint_every_s:
            t.c.wall_s = now
            t.c.last_ckpt_s = now
            t.checkpoint()

    def _unevaluated(self) -> bool:
        """Evaluations are on and the current network has not been evaluated yet."""
        cfg = self.t.cfg
        on = cfg.eval_every_updates > 0 or cfg.eval_every_s > 0
        return on and self.t.c.last_eval_updates != self.t.agent.updates

    def _eval_due(self, now: float) -> bool:
        """A periodic evaluation is due: by gradient updates (`eval_every_updates`) or else by
        wall time (`eval_every_s`)."""
        t, cfg = self.t, self.t.cfg
        if cfg.eval_every_updates > 0:
            return t.agent.updates - max(t.c.last_eval_updates, 0) >= cfg.eval_every_updates
        return cfg.eval_every_s > 0 and now - t.c.last_eval_s >= cfg.eval_every_s

    def _periodic_eval(self) -> None:
        """Evaluate the current network; a better one (success, then median fuel) is best.pt."""
        t = self.t
        ev = t.evaluate()
        now = self.now()
        t.c.last_eval_s = now
        t.c.last_eval_updates = t.agent.updates
        t.c.wall_s = now
        key = (ev["success_rate"], -ev["fuel_median"])
        if key > tuple(t.c.best_eval):
            t.c.best_eval = key
            t.save_policies("best", {"periodic_eval": ev})
        self.emit("on_eval", ev, now)  # after best.pt: a sweep's scheduler may stop the run here
