"""Which part of a navigation bias loses the landing? (issue 68)

    python bench/nav_bias_probe.py [SPEC ...] [--episodes 500] [--seed 68000000]
        [--dispersions data/beyond.yaml] [--scenario nav-bias] [--zemzev-slope S ...]

Flies `--episodes` episodes of a scenario with a constant navigation bias
(`Dispersions.nav_position_bias_m`, `nav_velocity_bias_mps`: a random direction in 3-D, so the
bias has a vertical part) with each agent (`pd-eval` specs, default the shipped file), all on the
same episodes, and prints for each: the success, the success per bin of the vertical position
bias (observed minus true altitude), and how the failures end: out of time, off the pad (Eq. 12's
5 m) or too fast. A lander that believes it is higher than it is meets the ground at the descent
speed its profile has at the believed altitude, so the table beside it gives each agent's descent
speed where it believed it was 1, 3 and 5 m up (medians over the episodes that passed there), and
the mean fuel of the same number of nominal episodes (seed 0): what a slower final descent costs.
`--zemzev-slope S` adds ZEM/ZEV-vernier behind the default layer with its final descent no faster
than 0.5 m/s + S z (`ZemZevParams.final_slope_per_s`, 0.3/s in the shipped law).

The information bound: the bias is constant, so nothing the lander observes reveals the position
part of it. A lander that lands exactly on its estimate of the pad lands |lateral bias| from the
real one; the line "lateral bias > X m" counts the episodes where a miss of 5 m - X in the wrong
direction already fails, whatever the controller.
"""

from __future__ import annotations

import argparse
import os
from dataclasses import replace

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from pd_core.dispersions import load_scenarios  # noqa: E402
from pd_core.episodes import rollout  # noqa: E402
from pd_core.reward import missed_limits  # noqa: E402
from pd_core.runtime.build import Built, build  # noqa: E402
from pd_core.runtime.config import RuntimeConfig  # noqa: E402
from pd_core.runtime.layer import Runtime  # noqa: E402
from pd_core.runtime.policy_file import SHIPPED_POLICY  # noqa: E402
from pd_core.teachers.zemzev import VERNIER_PARAMS, ZemZevController  # noqa: E402
from pd_core.vector_env import make_vector_env  # noqa: E402

Z_BINS_M = (-5.0, -2.0, -0.5, 0.5, 2.0, 5.0)
BELIEVED_ALTITUDES_M = (1.0, 3.0, 5.0)
KEPT = 200  # trajectories kept per agent for the descent speeds


def descent_speed_at(paths: list[np.ndarray], bias: np.ndarray, altitude_m: float) -> float:
    """Median observed descent speed (m/s) where each path first believed it was `altitude_m`
    up (true altitude + vertical bias), over the paths that got there; NaN if none did."""
    speeds = []
    for path, b in zip(paths, bias, strict=True):
        believed = path[:, 2] + b[2]
        below = np.flatnonzero(believed <= altitude_m)
        if len(below) and below[0] > 0:
            speeds.append(-(path[below[0], 5] + b[5]))
    return float(np.median(speeds)) if speeds else float("nan")


def zemzev_slope(slope_per_s: float) -> Built:
    """ZEM/ZEV-vernier behind the default layer, final descent no faster than 0.5 + slope z."""
    law = ZemZevController(replace(VERNIER_PARAMS, final_slope_per_s=slope_per_s))
    name = f"zemzev-vernier, slope {slope_per_s:g}/s"
    return Built(Runtime(law, RuntimeConfig(), name=name), f"controller {name} + layer")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("specs", nargs="*", default=[str(SHIPPED_POLICY)])
    ap.add_argument("--episodes", type=int, default=500)
    ap.add_argument("--seed", type=int, default=68_000_000)
    ap.add_argument("--dispersions", default="data/beyond.yaml")
    ap.add_argument("--scenario", default="nav-bias")
    ap.add_argument("--zemzev-slope", type=float, nargs="*", default=[])
    a = ap.parse_args(argv)
    (d,) = [s for s in load_scenarios(a.dispersions) if s.name == a.scenario]
    if not d.has_nav_bias:
        raise SystemExit(f"{a.scenario}: no navigation bias")
    n = a.episodes
    env = make_vector_env(n, autoreset=False, dispersions=d)
    env.reset(seed=a.seed)
    bias = env.state_dict()["nav_bias"]
    lateral = np.hypot(bias[:, 0], bias[:, 1])
    print(f"{a.scenario}: {n} episodes, seed {a.seed}")
    for x in (4.0, 4.5, 4.8):
        print(f"  lateral bias > {x} m: {int((lateral > x).sum())} episodes")
    bins = list(zip(Z_BINS_M[:-1], Z_BINS_M[1:], strict=True))
    in_bin = [(bias[:, 2] >= lo) & (bias[:, 2] < hi) for lo, hi in bins]
    print(
        "  vertical bias bins (m): "
        + ", ".join(
            f"[{lo:+g}, {hi:+g}) {int(m.sum())}" for (lo, hi), m in zip(bins, in_bin, strict=True)
        )
    )
    for built in [build(spec) for spec in a.specs] + [zemzev_slope(s) for s in a.zemzev_slope]:
        ro = rollout(built.actor, n, a.seed, dispersions=d, keep_trajectories=KEPT)
        off, too_fast = missed_limits(ro.final_states[:, 0:3], ro.final_states[:, 3:6])
        failed = ~ro.landed
        late, far = failed & ~ro.terminated, failed & ro.terminated & off
        fast = failed & ro.terminated & too_fast & ~off
        per_bin = " ".join(f"{ro.landed[m].mean():6.1%}" if m.any() else "     -" for m in in_bin)
        speeds = " ".join(
            f"{descent_speed_at(ro.trajectories, bias[:KEPT], h):.2f}" for h in BELIEVED_ALTITUDES_M
        )
        nominal = rollout(built.actor, n, 0)
        print(
            f"{built.label}: landed {ro.landed.mean():.1%}; per bin {per_bin}; failed: out of "
            f"time {int(late.sum())}, off the pad {int(far.sum())}, too fast {int(fast.sum())}; "
            f"descent m/s believed at 1/3/5 m {speeds}; lateral bias > 4.5 m landed "
            f"{int(ro.landed[lateral > 4.5].sum())}/{int((lateral > 4.5).sum())}; nominal "
            f"{nominal.landed.mean():.1%}, fuel {nominal.fuel_kg.mean():.1f} kg"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
