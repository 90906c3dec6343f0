"""How a policy's landings end, failed beside landed, in one run: the last seconds before
touchdown, per lateral and vertical axis, with what the ZEM/ZEV-vernier law (the teacher's
fallback in its last 2 s) would command on the same true states.

    python bench/touchdown_anatomy.py [--policy models/pd_dqn_ocp.pt] [--scenario all]
                                      [--campaign standard] [--episodes 2000] [--seed 0]
                                      [--last-s 2.0] [--show 3]

Flies the scenario's episodes through `pd_core.episodes.rollout`, as `pd-eval
--dispersions CAMPAIGN` does (episode i on seed seed + i: the same flights), recording every
decision (`Runtime.step_rows`).
For the failed and the landed episodes it prints, over the last `--last-s` seconds: the median
lateral and vertical speed at touchdown; the share of steps on which the flown lateral command
brakes the lateral velocity (opposes it on an axis moving faster than 0.2 m/s), is zero, or
pushes; the share on which the flown (i, j) levels equal the vernier law's; and who decided.
Then the last steps of the first `--show` failures, step by step.
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from pd_core.actions import DEFAULT_ACTIONS
from pd_core.config import DT_S
from pd_core.dispersions import Dispersions, load_scenarios
from pd_core.episodes import rollout
from pd_core.runtime.build import build
from pd_core.runtime.decision import SOURCES
from pd_core.runtime.layer import Runtime
from pd_core.runtime.policy_file import SHIPPED_POLICY
from pd_core.teachers.registry import make_controller

MOVING_MPS = 0.2  # a lateral axis faster than this is "moving" for the braking share


class DecisionLog:
    """`Runtime.step_rows` behind the row-wise actor interface `rollout` flies, keeping the
    proposed action and who decided for every row of every chunk."""

    def __init__(self, rt: Runtime) -> None:
        self.rt = rt
        self.chunks: list[list[list[tuple[int, int]]]] = []

    def begin_episodes(self, n: int) -> None:
        self.rt.begin_episodes(n)
        self.chunks.append([[] for _ in range(n)])

    def act_rows(self, states: np.ndarray, rows: np.ndarray) -> np.ndarray:
        actions, dec = self.rt.step_rows(states, rows)
        rec = self.chunks[-1]
        for b, i in enumerate(rows):
            rec[i].append((int(dec.proposed[b]), int(dec.source[b])))
        return actions


def fly(policy: str, scenario: Dispersions, episodes: int, seed: int) -> list[dict[str, Any]]:
    """Per episode: true states (T+1, 7), flown and proposed actions (T,), sources (T,), landed."""
    log = DecisionLog(build(policy).runtime)
    ro = rollout(log, episodes, seed, dispersions=scenario, keep_trajectories=episodes)
    decided = [np.array(r, dtype=np.int64).reshape(-1, 2) for c in log.chunks for r in c]
    return [
        {"states": x, "action": a, "proposed": d[:, 0], "source": d[:, 1], "landed": bool(ok)}
        for x, a, d, ok in zip(ro.trajectories, ro.actions, decided, ro.landed, strict=True)
    ]


def tail_stats(eps: list[dict[str, Any]], steps: int, vernier: object) -> dict[str, float]:
    """Shares over the last `steps` decisions of each episode, and touchdown speeds."""
    levels = DEFAULT_ACTIONS.level_table
    mid = (np.array(DEFAULT_ACTIONS.n_per_axis[:2]) - 1) // 2
    brake = zero = push = same = 0
    n = 0
    src = np.zeros(len(SOURCES))
    lat_td, vert_td = [], []
    for e in eps:
        s = e["states"][:-1][-steps:]
        a = e["action"][-steps:]
        flown = levels[a][:, :2]
        lv = flown - mid  # signed lateral levels, 0 = no thrust
        v = s[:, 3:5]
        moving = np.abs(v) > MOVING_MPS
        opposes = moving & (np.sign(lv) == -np.sign(v)) & (lv != 0)
        pushes = moving & (np.sign(lv) == np.sign(v)) & (lv != 0)
        brake += int(opposes.any(axis=1).sum())
        push += int((pushes.any(axis=1) & ~opposes.any(axis=1)).sum())
        zero += int((lv == 0).all(axis=1).sum())
        same += int((flown == levels[vernier.act_batch(s)][:, :2]).all(axis=1).sum())
        src += np.bincount(e["source"][-steps:], minlength=len(SOURCES))
        n += len(a)
        end = e["states"][-1]
        lat_td.append(float(np.hypot(end[3], end[4])))
        vert_td.append(float(-end[5]))
    return {
        "episodes": len(eps),
        "steps": n,
        "lateral_td": float(np.median(lat_td)) if lat_td else float("nan"),
        "vertical_td": float(np.median(vert_td)) if vert_td else float("nan"),
        "brake": brake / max(n, 1),
        "zero": zero / max(n, 1),
        "push": push / max(n, 1),
        "as_vernier": same / max(n, 1),
        **{f"by_{name}": src[k] / max(n, 1) for k, name in enumerate(SOURCES)},
    }


def show(e: dict[str, Any], steps: int, vernier: object) -> None:
    levels = DEFAULT_ACTIONS.level_table
    s = e["states"][:-1][-steps:]
    print(f"{'z m':>7} {'vx':>6} {'vy':>6} {'vz':>6}  flown  proposed  vernier  by")
    vz = levels[vernier.act_batch(s)]
    for k in range(len(s)):
        a, p, src = e["action"][-steps:][k], e["proposed"][-steps:][k], e["source"][-steps:][k]
        print(
            f"{s[k, 2]:7.2f} {s[k, 3]:6.2f} {s[k, 4]:6.2f} {s[k, 5]:6.2f}  "
            f"{levels[a]!s:>7}  {levels[p]!s:>8}  {vz[k]!s:>7}  {SOURCES[src]}"
        )
    end = e["states"][-1]
    print(f"touchdown: lateral {np.hypot(end[3], end[4]):.2f} m/s, vertical {-end[5]:.2f} m/s\n")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--policy", default=str(SHIPPED_POLICY))
    ap.add_argument("--campaign", default="standard")
    ap.add_argument("--scenario", default="all", help="scenario name in the campaign")
    ap.add_argument("--episodes", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--last-s", type=float, default=2.0, help="seconds before touchdown")
    ap.add_argument("--show", type=int, default=3, help="failures printed step by step")
    a = ap.parse_args()
    if a.episodes < 1 or a.last_s <= 0:
        ap.error("--episodes must be >= 1 and --last-s > 0")
    scenarios = {d.name: d for d in load_scenarios(a.campaign)}
    if a.scenario not in scenarios:
        ap.error(f"--scenario must be one of {', '.join(scenarios)}")
    eps = fly(a.policy, scenarios[a.scenario], a.episodes, a.seed)
    steps = max(1, round(a.last_s / DT_S))
    vernier = make_controller("zemzev-vernier")
    failed = [e for e in eps if not e["landed"]]
    landed = [e for e in eps if e["landed"]]
    print(f"{a.policy}, {a.campaign}/{a.scenario}, {a.episodes} episodes from seed {a.seed}")
    print(f"last {a.last_s:g} s ({steps} decisions) of each episode:")
    keys = ["episodes", "lateral_td", "vertical_td", "brake", "zero", "push", "as_vernier"]
    keys += [f"by_{n}" for n in SOURCES]
    rows = {
        "failed": tail_stats(failed, steps, vernier),
        "landed": tail_stats(landed, steps, vernier),
    }
    print(f"{'':>16}" + "".join(f"{k:>10}" for k in rows))
    for k in keys:
        fmt = "{:>10.0f}" if k == "episodes" else "{:>10.2f}" if k.endswith("_td") else "{:>10.1%}"
        print(f"{k:>16}" + "".join(fmt.format(rows[r][k]) for r in rows))
    print("(lateral_td / vertical_td: median touchdown speeds, m/s; brake / zero / push: share")
    print(" of steps whose flown lateral command opposes / is zero / pushes a moving axis;")
    print(" as_vernier: flown (i, j) equal to the vernier law's on the true state)\n")
    for e in failed[: a.show]:
        show(e, steps, vernier)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
