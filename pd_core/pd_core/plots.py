"""Figures: training curves, and Figs. 5-8 of the paper from training logs and evaluations.

matplotlib is imported lazily with the Agg backend, so this module loads on headless machines.
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

import numpy as np


def _plt() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def read_csv(path: str | Path) -> dict[str, np.ndarray]:
    """Columns of a CSV log as float arrays (empty arrays for an empty log)."""
    with Path(path).open() as f:
        rows = list(csv.reader(f))
    if not rows:
        return {}
    head, body = rows[0], rows[1:]
    cols = {h: np.array([float(r[i]) for r in body], dtype=float) for i, h in enumerate(head)}
    return cols


def training_curves(run_dir: str | Path, out: str | Path) -> Path:
    """2x3 panels: return, success rate, loss, epsilon against episodes; eval success and fuel
    against wall time."""
    plt = _plt()
    rd = Path(run_dir)
    ep = read_csv(rd / "episodes.csv") if (rd / "episodes.csv").exists() else {}
    m = read_csv(rd / "metrics.csv") if (rd / "metrics.csv").exists() else {}
    ev = read_csv(rd / "evals.csv") if (rd / "evals.csv").exists() else {}
    fig, ax = plt.subplots(2, 3, figsize=(13, 7))
    if ep.get("episode") is not None and len(ep["episode"]):
        x = ep["episode"]
        ax[0, 0].plot(x, ep["return"], ".", ms=1, alpha=0.3, color="grey")
        ax[0, 0].plot(x, _running(ep["return"], 100), color="C0")
        ax[0, 1].plot(x, _running(ep["landed"], 100), color="C1", label="training (eps-greedy)")
        ax[1, 1].plot(x, ep["epsilon"], color="C3")
    ax[0, 0].set(xlabel="episode", ylabel="return", title="training return (100-ep mean)")
    ax[0, 1].set(xlabel="episode", ylabel="success rate", title="training success (100-ep)")
    if m.get("updates") is not None and len(m["updates"]):
        ax[1, 0].semilogy(m["updates"], np.abs(m["loss"]), label="total")
        ax[1, 0].semilogy(m["updates"], np.abs(m["td_loss"]), label="TD")
        if np.any(np.isfinite(m["margin_loss"])):
            ax[1, 0].semilogy(m["updates"], np.abs(m["margin_loss"]), label="margin")
        ax[1, 0].legend()
    ax[1, 0].set(xlabel="gradient update", ylabel="loss", title="loss")
    ax[1, 1].set(xlabel="episode", ylabel="epsilon", title="exploration")
    if ev.get("wall_s") is not None and len(ev["wall_s"]):
        mins = ev["wall_s"] / 60.0
        ax[0, 2].plot(mins, ev["success_rate"], "o-", label="success")
        ax[0, 2].plot(mins, ev["soft_landing_rate"], "s--", label="soft landing")
        ax[0, 2].legend()
        ax[1, 2].plot(mins, ev["fuel_median"], "o-", color="C2")
    ax[0, 2].set(
        xlabel="wall time (min)",
        ylabel="rate",
        title="greedy eval vs wall time",
        ylim=(-0.02, 1.02),
    )
    ax[1, 2].set(xlabel="wall time (min)", ylabel="median fuel (kg)", title="greedy eval fuel")
    fig.tight_layout()
    fig.savefig(out, dpi=80)
    plt.close(fig)
    return Path(out)


def _running(x: np.ndarray, n: int) -> np.ndarray:
    c = np.cumsum(np.insert(np.asarray(x, float), 0, 0.0))
    idx = np.arange(1, len(x) + 1)
    lo = np.maximum(idx - n, 0)
    return (c[idx] - c[lo]) / (idx - lo)


def fig5_cumulative_successes(logs: dict[str, str | Path], out: str | Path) -> Path:
    """Fig. 5: cumulative successful training episodes against episode, one line per run."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 4))
    for name, path in logs.items():
        ep = read_csv(path)
        if ep and len(ep["episode"]):
            ax.plot(ep["episode"], np.cumsum(ep["landed"]), label=name)
    ax.set(xlabel="episode", ylabel="cumulative successful episodes", title="Fig. 5")
    if ax.get_legend_handles_labels()[0]:
        ax.legend()
    fig.tight_layout()
    fig.savefig(out, dpi=90)
    plt.close(fig)
    return Path(out)


def fig6_trajectory(
    states: np.ndarray, thrust_n: np.ndarray, dt_s: float, out: str | Path, title: str = ""
) -> Path:
    """Fig. 6: position, velocity and thrust against time of one episode."""
    plt = _plt()
    t = np.arange(len(states)) * dt_s
    fig, ax = plt.subplots(3, 1, figsize=(7, 8), sharex=True)
    names = ("i", "j", "k")
    for k in range(3):
        ax[0].plot(t, states[:, k], label=f"{names[k]}-position")
        ax[1].plot(t, states[:, 3 + k], label=f"{names[k]}-velocity")
        if len(thrust_n):
            ax[2].step(t[:-1], thrust_n[:, k], where="post", label=f"T{k + 1}")
    for a, y in zip(ax, ("position (m)", "velocity (m/s)", "thrust (N)"), strict=True):
        a.axhline(0.0, color="grey", lw=0.8)
        a.set_ylabel(y)
        a.legend(fontsize=8)
    ax[2].set_xlabel("time (s)")
    ax[0].set_title(title or "Fig. 6: example trajectory")
    fig.tight_layout()
    fig.savefig(out, dpi=80)
    plt.close(fig)
    return Path(out)


def fig7_final_distributions(finals: dict[str, np.ndarray], out: str | Path) -> Path:
    """Fig. 7: histograms of final i/j/k position and velocity; one row per agent (each panel
    has its own range, so a tight agent is not squashed by a scattered one)."""
    plt = _plt()
    n = len(finals)
    fig, ax = plt.subplots(n, 6, figsize=(16, 2.4 * n + 0.6), squeeze=False)
    labels = (
        "i-position (m)",
        "j-position (m)",
        "k-position (m)",
        "i-velocity (m/s)",
        "j-velocity (m/s)",
        "k-velocity (m/s)",
    )
    for r, (name, f) in enumerate(finals.items()):
        for k in range(6):
            ax[r, k].hist(f[:, k], bins=40, color=f"C{r}")
            ax[r, k].set_xlabel(f"final {labels[k]}", fontsize=8)
            ax[r, k].tick_params(labelsize=7)
        ax[r, 0].set_ylabel(f"{name}\nepisodes", fontsize=8)
    fig.suptitle("Fig. 7: distributions of final states")
    fig.tight_layout()
    fig.savefig(out, dpi=70)
    plt.close(fig)
    return Path(out)


def fig8_initial_j_vs_final_i(
    initial: np.ndarray, final: np.ndarray, out: str | Path, name: str = ""
) -> Path:
    """Fig. 8: initial j-position against final i-position."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.scatter(initial[:, 1], final[:, 0], s=4)
    ax.set(
        xlabel="initial j-position (m)",
        ylabel="final i-position (m)",
        title=f"Fig. 8 {name}".strip(),
    )
    fig.tight_layout()
    fig.savefig(out, dpi=80)
    plt.close(fig)
    return Path(out)


def success_vs_wall_time(runs: dict[str, str | Path], out: str | Path) -> Path:
    """Greedy-eval success rate against wall time for several runs (from evals.csv)."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 4))
    for name, rd in runs.items():
        ev = read_csv(Path(rd) / "evals.csv")
        if ev and len(ev["wall_s"]):
            ax.plot(ev["wall_s"] / 60.0, ev["success_rate"], "o-", ms=3, label=name)
    ax.set(xlabel="wall time (min)", ylabel="success rate (greedy eval)", ylim=(-0.02, 1.02))
    if ax.get_legend_handles_labels()[0]:
        ax.legend()
    fig.tight_layout()
    fig.savefig(out, dpi=90)
    plt.close(fig)
    return Path(out)


def campaign_summary(t: dict[str, Any], out: str | Path) -> Path:
    """A dispersion campaign (`pd_core.experiments.campaign.table`): success, 99th-percentile miss
    and median
    fuel per scenario, one bar per agent."""
    plt = _plt()
    names = [d["name"] for d in t["scenarios"]]
    agents = t["agents"]
    panels = (
        ("success_rate", "success (%)", 100.0),
        ("miss_p99_m", "miss, 99th percentile (m)", 1.0),
        ("fuel_median_kg", "median fuel (kg)", 1.0),
    )
    fig, ax = plt.subplots(len(panels), 1, figsize=(max(6, 0.9 * len(names) + 2), 8), sharex=True)
    x = np.arange(len(names))
    w = 0.8 / max(len(agents), 1)
    for p, (key, label, scale) in enumerate(panels):
        for j, a in enumerate(agents):
            v = [t["results"][n][a][key] * scale for n in names]
            ax[p].bar(x + (j - (len(agents) - 1) / 2) * w, v, w, label=a, color=f"C{j}")
        ax[p].set_ylabel(label, fontsize=8)
        ax[p].grid(axis="y", alpha=0.3)
    lo = min(t["results"][n][a]["success_rate"] for n in names for a in agents) * 100
    ax[0].set_ylim(max(0.0, lo - 5.0), 100.5)
    ax[1].set_yscale("log")  # metres to hundreds of metres
    ax[0].legend(fontsize=8, ncol=max(1, len(agents)))
    ax[-1].set_xticks(x, names, rotation=30, ha="right")
    ax[0].set_title(f"dispersion campaign: {t['episodes']} episodes per cell, seed {t['seed']}")
    fig.tight_layout()
    fig.savefig(out, dpi=80)
    plt.close(fig)
    return Path(out)


def sweep_success_bands(
    curves: dict[str, list[tuple[np.ndarray, np.ndarray]]], out: str | Path
) -> Path:
    """Success rate of periodic evaluations against wall time (min) for the configurations of a
    sweep: a line per configuration (mean over seeds) with its seed band (min to max), on the
    union of the seeds' evaluation times (each seed held at its last value)."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for c, (name, runs) in enumerate(curves.items()):
        runs = [(t, s) for t, s in runs if len(t)]
        if not runs:
            continue
        grid = np.unique(np.concatenate([t for t, _ in runs]))
        ys = np.array([np.interp(grid, t, s, left=np.nan) for t, s in runs])
        with np.errstate(all="ignore"):
            mean, lo, hi = np.nanmean(ys, 0), np.nanmin(ys, 0), np.nanmax(ys, 0)
        ax.plot(grid, mean, "-", color=f"C{c}", label=f"{name} ({len(runs)} seeds)")
        ax.fill_between(grid, lo, hi, color=f"C{c}", alpha=0.2, lw=0)
    ax.set(xlabel="wall time (min)", ylabel="success rate (greedy eval)", ylim=(-0.02, 1.02))
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=90)
    plt.close(fig)
    return Path(out)


def flight_vs_ocp(
    path: str | Path,
    states: np.ndarray,
    thrust: np.ndarray,
    ocp: dict[str, np.ndarray] | None,
    title: str,
    dt_s: float = 0.2,
    flight_label: str = "flight over ROS 2",
) -> Path:
    """A flight (left: states (N+1, 7) every dt_s, thrust (N, 3) held over each step) beside the
    OCP trajectory (right: `ocp` dict with state_times, states, control_times, thrust, or None):
    position, velocity and thrust against time."""
    plt = _plt()
    t = np.arange(len(states)) * dt_s
    none = {"state_times": t[:0], "states": np.zeros((0, 7))}
    ocp = ocp or {**none, "control_times": t[:0], "thrust": np.zeros((0, 3))}
    fig, ax = plt.subplots(3, 2, figsize=(12, 9), sharex=True, sharey="row")
    names = ("i (downrange)", "j (crossrange)", "k (altitude)")
    cols = [
        (flight_label, t, states, t[: len(thrust)], thrust, "post"),
        ("optimal trajectory", ocp["state_times"], ocp["states"], ocp["control_times"],
         ocp["thrust"], None),
    ]  # fmt: skip
    for c, (head, ts, s, tu, u, where) in enumerate(cols):
        for k in range(3):
            if len(s):
                ax[0, c].plot(ts, s[:, k], label=names[k])
                ax[1, c].plot(ts, s[:, 3 + k], label=names[k])
            if len(u) and where:
                ax[2, c].step(tu, u[:, k], where=where, label=f"T{k + 1}")
            elif len(u):
                ax[2, c].plot(tu, u[:, k], ".-", ms=3, label=f"T{k + 1}")
        ax[0, c].set_title(head)
        for r, ylabel in enumerate(("position (m)", "velocity (m/s)", "thrust (N)")):
            ax[r, c].axhline(0.0, color="grey", lw=0.7)
            ax[r, c].legend(fontsize=7)
            if c == 0:
                ax[r, c].set_ylabel(ylabel)
        ax[2, c].set_xlabel("time (s)")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return Path(path)
