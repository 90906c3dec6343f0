"""Where an MPC teacher's fuel goes, per episode (issue 32, stage 1): measured, not guessed.

    python bench/mpc_diagnose.py [--controller mpc-fuel] [--episodes 20] [--seed 0] [--bare]

Flies `--episodes` nominal Table 3 episodes (disturbances on, episode i on seed `--seed` + i,
the episodes `pd-eval --fuel-optimal` uses) with the controller behind the runtime layer
(`Runtime(make_controller(NAME), RuntimeConfig())`, as `layer:controller:NAME`; `--bare`: no
layer), one episode at a time, and prints per episode and as medians:

* fuel / the unreserved fuel-optimal landing from the same state (`ocp.solve`, RL limits);
* the first (cold) plan's predicted fuel to its gate / that optimum (what the plans cost);
* the share of steps on the ZEM/ZEV fallback, and the fuel burnt on it;
* the share of steps the layer changed (brake, guard, handover);
* the share of warm re-plans that needed the full RL limits (the plan margin had no plan).
"""

from __future__ import annotations

import argparse
import os
from dataclasses import replace

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from pd_core import ocp  # noqa: E402
from pd_core.config import RL_THRUST  # noqa: E402
from pd_core.episodes import rollout  # noqa: E402
from pd_core.runtime.config import RuntimeConfig  # noqa: E402
from pd_core.runtime.decision import SOURCES  # noqa: E402
from pd_core.runtime.layer import Runtime  # noqa: E402
from pd_core.teachers.mpc import MPCController  # noqa: E402
from pd_core.teachers.registry import make_controller  # noqa: E402


def _settings(text: str) -> dict[str, object]:
    """{name: value} of "k=v,k=v" (numbers as float, else the string)."""
    out: dict[str, object] = {}
    for kv in text.split(","):
        k, _, v = kv.partition("=")
        try:
            out[k.strip()] = float(v) if "." in v or "e" in v else int(v)
        except ValueError:
            out[k.strip()] = v.strip()
    return out


class _Recorder:
    """Wraps the MPC controller: per step, whether the fallback flew it."""

    def __init__(self, ctl: MPCController) -> None:
        self.ctl = ctl
        self.name = ctl.name
        self.fallback_flags: list[bool] = []
        self.first_plan_fuel = np.nan

    def act_batch(self, states: np.ndarray) -> np.ndarray:
        before = self.ctl.stats.fallback_steps
        out = self.ctl.act_batch(states)
        self.fallback_flags.append(self.ctl.stats.fallback_steps > before)
        if len(self.fallback_flags) == 1 and self.ctl._rows and self.ctl._rows[0].p is not None:
            row = self.ctl._rows[0]
            pb = self.ctl._problem.at(self.ctl._to_gate(states[0]), n_control=len(row.p))
            self.first_plan_fuel = pb.fly(row.p, pb.grid(row.t_go)).fuel
        return out


class _Layer:
    """Runtime wrapper recording each step's decision source (rollout calls act_rows)."""

    def __init__(self, rt: Runtime) -> None:
        self.rt = rt
        self.sources: list[int] = []

    def begin_episodes(self, n: int) -> None:
        self.rt.begin_episodes(n)

    def act_rows(self, states: np.ndarray, rows: np.ndarray) -> np.ndarray:
        a, dec = self.rt.step_rows(states, rows)
        self.sources.append(int(dec.source[0]))
        return a


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--controller", default="mpc-fuel")
    ap.add_argument("--episodes", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--bare", action="store_true", help="no runtime layer")
    ap.add_argument("--quiet", action="store_true", help="medians only")
    ap.add_argument(
        "--set",
        default="",
        help="MPCParams changed, e.g. rounding=nearest,plan_thrust_fraction=0.85",
    )
    a = ap.parse_args(argv)
    where = "" if a.bare else " + layer"
    print(f"{a.controller}{where}: {a.episodes} nominal episodes, seed {a.seed}")
    head = (
        f"{'ep':>3} {'ok':>3} {'fuel':>6} {'/opt':>6} {'plan0/opt':>9} {'fb %':>5} "
        f"{'fb kg':>6} {'layer %':>7} {'brake':>5} {'guard':>5} {'hand':>4} {'steps':>5}"
    )
    if not a.quiet:
        print(head)
    rows = []
    full, warm = 0, 0  # warm re-plans on the full limits (recovery), all warm re-plans
    for i in range(a.episodes):
        ctl = make_controller(a.controller)
        if a.set and isinstance(ctl, MPCController):
            ctl = MPCController(replace(ctl.params, **_settings(a.set)), ctl.fallback)
        rec = _Recorder(ctl) if isinstance(ctl, MPCController) else None
        actor = rec or ctl
        wrap = None if a.bare else _Layer(Runtime(actor, RuntimeConfig()))
        ro = rollout(wrap or actor, 1, a.seed + i, keep_trajectories=1)
        if rec:
            full, warm = full + ctl.stats.full_limits, warm + len(ctl.stats.warm)
        s0 = ro.initial_states[0]
        opt = ocp.solve(s0[0:3], s0[3:6], s0[6], objective="fuel", limits=RL_THRUST).fuel
        path = ro.trajectories[0]
        burn = -np.diff(path[:, 6])
        fb = np.array(rec.fallback_flags if rec else [False] * len(burn), dtype=bool)[: len(burn)]
        src = np.array(wrap.sources if wrap else [0] * len(burn))[: len(burn)]
        counts = np.bincount(src, minlength=len(SOURCES))
        n = len(burn)
        r = [
            i,
            int(ro.landed[0]),
            float(ro.fuel_kg[0]),
            float(ro.fuel_kg[0] / opt),
            (rec.first_plan_fuel / opt) if rec else np.nan,
            100.0 * fb.mean(),
            float(burn[fb].sum()),
            100.0 * (src != 0).mean(),
            int(counts[1]),
            int(counts[2]),
            int(counts[3]),
            n,
        ]
        rows.append(r)
        if not a.quiet:
            print(
                f"{r[0]:>3} {r[1]:>3} {r[2]:>6.1f} {r[3]:>6.3f} {r[4]:>9.3f} {r[5]:>5.1f} "
                f"{r[6]:>6.1f} {r[7]:>7.1f} {r[8]:>5} {r[9]:>5} {r[10]:>4} {r[11]:>5}",
                flush=True,
            )
    m = np.array(rows, dtype=float)
    tot = m[:, 11].sum()
    fb_share = (m[:, 5] * m[:, 11]).sum() / tot  # percent of all steps
    changed = (m[:, 7] * m[:, 11]).sum() / tot
    plan0 = np.nanmedian(m[:, 4]) if np.isfinite(m[:, 4]).any() else np.nan
    print(
        f"median fuel/opt {np.median(m[:, 3]):.3f}, first plan/opt {plan0:.3f}, "
        f"success {100 * m[:, 1].mean():.1f} %, fallback {fb_share:.1f} % "
        f"of steps ({np.median(m[:, 6]):.1f} kg median), layer changed "
        f"{changed:.2f} % of {int(tot)} steps "
        f"(brake {int(m[:, 8].sum())}, guard {int(m[:, 9].sum())}, handover {int(m[:, 10].sum())})"
        f"; re-plans on the full limits {100 * full / max(warm, 1):.2f} % of {warm}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
