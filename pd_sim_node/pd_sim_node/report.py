"""What pd_sim_node says about itself: its /diagnostics report of each period (`SimReport`;
levels: `pd_ros_common.diagnostics`), the lines it logs when an episode starts and ends
(`start_line`, `episode_line`), and where its simulator is, for the lifecycle lines (`where`).

/diagnostics (1 Hz): lander id, mode, target and achieved step rate, episode and step, and the
totals and last-period counts of steps, accepted, missed, rejected (by reason), lost and foreign
commands, and the other landers heard. ERROR when commands for another lander arrived in the
period; WARN when steps were flown without a command, commands were rejected or lost, or (real
time, flying the whole period) the achieved rate was under `diagnostics.RATE_SHORTFALL` of
rate_hz. The node adds its writers' reader counts (`diagnostics.readers`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pd_core.sim import Counters, Simulator
from pd_ros_common import diagnostics
from pd_ros_common.diagnostics import ERROR, WARN


class SimReport:
    """The report of each period: counts since the previous call (`diagnostics.Since`); the
    achieved rate over the wall-clock time between two calls."""

    def __init__(self, lander_id: str, lockstep: bool, rate_hz: float, now: float) -> None:
        self.lander_id = lander_id
        self.lockstep = lockstep
        self.rate_hz = rate_hz
        self._since = diagnostics.Since()
        self._at = now  # monotonic time of the previous report
        self._flying = False  # flying at the previous report

    def __call__(self, sim: Simulator, lost: int, now: float) -> diagnostics.Report:
        """The report of the period ending `now` (caller holds the simulator's lock)."""
        s, c = sim, sim.counters
        flying = s.flying
        d = self._since(
            steps=c.steps,
            missed=c.missed_commands,
            rejected=c.rejected_commands,
            foreign=c.foreign_commands,
            lost=lost,
        )
        others = sorted(c.foreign_by_lander)
        period = now - self._at
        rate = d["steps"] / period if period > 0 else 0.0
        whole_period = flying and self._flying and not self.lockstep
        self._at, self._flying = now, flying
        r = diagnostics.Report(ok_message="flying" if flying else "idle")
        r.values = {
            "lander_id": self.lander_id,
            "mode": "lockstep" if self.lockstep else "real time",
            "rate_hz (target)": self.rate_hz if not self.lockstep else 0.0,
            "achieved rate (steps/s)": rate,
            "episode": s.episode,
            "step": s.step,
            "flying": flying,
            "steps": c.steps,
            "accepted commands": c.accepted_commands,
            "missed commands": c.missed_commands,
            "missed (last period)": int(d["missed"]),
            "rejected commands": c.rejected_commands,
            "rejected (last period)": int(d["rejected"]),
            "rejected by reason": ", ".join(
                f"{k} {v}" for k, v in sorted(c.rejected_by_reason.items())
            )
            or "none",
            "lost commands": lost,
            "foreign commands": c.foreign_commands,
            "foreign (last period)": int(d["foreign"]),
            "other landers": others or "none",
        }
        r.rule(
            ERROR,
            d["foreign"] > 0,
            f"{int(d['foreign'])} command(s) for other lander(s) {', '.join(others)}: a second "
            "stack shares these names",
        )
        r.rule(WARN, d["missed"] > 0, f"{int(d['missed'])} step(s) flown without a command")
        r.rule(WARN, d["rejected"] > 0, f"{int(d['rejected'])} command(s) rejected")
        r.rule(WARN, d["lost"] > 0, f"{int(d['lost'])} command(s) lost")
        r.rule(
            WARN,
            whole_period and rate < diagnostics.RATE_SHORTFALL * self.rate_hz,
            f"achieved {rate:.2f} steps/s of {self.rate_hz:g}",
        )
        return r


def episode_line(
    result: dict[str, Any], c: Counters, lost: int, lateness_ms: dict[str, float] | None
) -> str:
    """The line logged when an episode ends: its result, the totals so far and (real time) the
    tick lateness percentiles."""
    jitter = ""
    if lateness_ms is not None:
        jitter = f"; tick lateness p50 {lateness_ms['p50']:.3f} ms, p99 {lateness_ms['p99']:.3f} ms"
    return (
        f"episode {result['episode']} ended after {result['steps']} steps "
        f"({result['time_of_flight']:.1f} s): {result['reason']}; fuel "
        f"{result['fuel']:.1f} kg; commands rejected {result['rejected_commands']}, "
        f"missed {result['missed_commands']}, foreign {result['foreign_commands']} "
        f"(totals: accepted {c.accepted_commands}, rejected {c.rejected_commands}, missed "
        f"{c.missed_commands}, lost {lost}, foreign {c.foreign_commands})"
        f"{jitter}"
    )


def start_line(episode: int, init: np.ndarray) -> str:
    """The line logged when an episode starts from initial state `init`."""
    return (
        f"episode {episode} starts at x = {np.round(init[0:3], 2).tolist()} m, "
        f"v = {np.round(init[3:6], 2).tolist()} m/s, m = {init[6]:.1f} kg"
    )


def where(s: Simulator | None) -> str:
    """Which episode and step the simulator is at, for the lifecycle transitions' lines."""
    if s is None or not s.counters.episodes_started:
        return "no episode yet"
    return f"episode {s.episode} at step {s.step}" + ("" if s.flying else " (ended)")
