"""Where the fuel above the fuel-optimal landing goes, and how much of it a braking reserve costs
(issue 10's nominal fuel target, <= 1.05x), in one run.

    python bench/fuel_floor.py [--episodes 20] [--seed 0] [--agents models/pd_dqn_ocp.pt ...]

Part 1: the fuel-optimal landing (`pd_core.ocp.solve(objective="fuel")`, RL thrust limits) from the
first `--episodes` nominal Table 3 initial states of seed `--seed`, with the vertical thrust capped
at each `--fractions` of its 13 kN. A guidance law that keeps a reserve of (1 - f) of the vertical
thrust for thrust shortfalls, gusts and misalignment (the runtime layer counts on f = 0.9) cannot
land for less than the f row: its ratio to the full-thrust optimum is the floor for such a law.

Part 2: each agent (`pd-eval` specs: a policy file, `controller:NAME`, `layer:controller:NAME`)
flies the same episodes (disturbances on). Printed per agent: median fuel / fuel-optimal, flight
time, and the time and fuel spent in each altitude band (above 500 m, 500-20 m, below 20 m)
beside the optimum's, and the fuel burnt by the lateral (i, j) and the vertical (k) thrusters
(Eq. 3 burns |T_i| + |T_j| + |T_k|), to show where the extra fuel goes.
"""

from __future__ import annotations

import argparse
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from pd_core import ocp  # noqa: E402
from pd_core.actions import DEFAULT_ACTIONS  # noqa: E402
from pd_core.config import DT_S, RL_THRUST, ThrustLimits  # noqa: E402
from pd_core.dynamics import mass_flow_kgps  # noqa: E402
from pd_core.episodes import rollout  # noqa: E402
from pd_core.runtime.build import build  # noqa: E402
from pd_core.runtime.policy_file import SHIPPED_POLICY  # noqa: E402
from pd_core.teachers.registry import make_controller  # noqa: E402

BANDS_M = (500.0, 20.0)  # part 2 splits each flight at these altitudes


def capped(fraction: float) -> ThrustLimits:
    """RL thrust limits with the vertical maximum scaled by `fraction`."""
    hi = RL_THRUST.max_n
    return ThrustLimits(RL_THRUST.min_n, (hi[0], hi[1], fraction * hi[2]))


def bands(z_m: np.ndarray, t_s: np.ndarray, m_kg: np.ndarray) -> list[float]:
    """[time s, fuel kg] of each altitude band (above BANDS_M[0], ..., below BANDS_M[-1])."""
    cuts = [0] + [int(np.argmax(z_m < h)) for h in BANDS_M] + [len(z_m) - 1]
    out: list[float] = []
    for i, j in zip(cuts[:-1], cuts[1:], strict=True):
        out += [float(t_s[j] - t_s[i]), float(m_kg[i] - m_kg[j])]
    return out


def axis_split(thrust_n: np.ndarray, dt_s: np.ndarray, total_kg: float) -> list[float]:
    """[lateral kg, vertical kg] burnt by thrusts (n, 3) held dt_s (n,), scaled to total_kg
    (the OCP's thrust is a spline between control points: its control points give the shares)."""
    lateral = float((mass_flow_kgps(thrust_n[:, 0:2]) * dt_s).sum())
    vertical = float((mass_flow_kgps(thrust_n[:, 2:3]) * dt_s).sum())
    scale = total_kg / max(lateral + vertical, 1e-9)
    return [float(lateral * scale), float(vertical * scale)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--episodes", type=int, default=20, help="initial states (default 20)")
    ap.add_argument("--seed", type=int, default=0, help="episode seed of the first state")
    ap.add_argument("--fractions", type=float, nargs="+", default=[1.0, 0.95, 0.9, 0.85])
    ap.add_argument(
        "--agents",
        nargs="+",
        default=[str(SHIPPED_POLICY), "controller:zemzev", "layer:controller:zemzev"],
        help="pd-eval agent specs flown in part 2",
    )
    a = ap.parse_args()
    if a.episodes < 1 or not all(0.5 <= f <= 1.0 for f in a.fractions):
        ap.error("--episodes must be >= 1 and every --fractions value in [0.5, 1]")

    starts = rollout(make_controller("zemzev"), a.episodes, a.seed).initial_states
    print(f"Part 1: fuel-optimal landings from {a.episodes} nominal states (seed {a.seed})")
    print(f"{'vertical max':>12} {'fuel p50 kg':>11} {'t_f p50 s':>9} {'ratio p50':>9}  min    max")
    optimum, top, solved = None, 1.0, {}
    for f in sorted(a.fractions, reverse=True):
        sols = [ocp.solve(s[0:3], s[3:6], s[6], objective="fuel", limits=capped(f)) for s in starts]
        fuel = np.array([r.fuel for r in sols])
        if optimum is None:  # the largest fraction is the reference (1.0 by default)
            optimum, top = fuel, f
        solved[f] = sols
        ratio = fuel / optimum
        tf = np.median([r.time_of_flight for r in sols])
        print(
            f"{f:>12.2f} {np.median(fuel):>11.1f} {tf:>9.1f} {np.median(ratio):>9.3f} "
            f"{ratio.min():>6.3f} {ratio.max():>6.3f}"
        )
    print(f"\nPart 2: agents on the same states, fuel against the optimum at {top:.2f}")
    names = [f"z>{BANDS_M[0]:.0f}"] + [
        f"{lo:.0f}-{hi:.0f}" for hi, lo in zip(BANDS_M[:-1], BANDS_M[1:], strict=True)
    ]
    names.append(f"z<{BANDS_M[-1]:.0f}")
    band_head = " ".join(f"{n + ' s/kg':>14}" for n in names)
    print(f"{'agent':<28} {'fuel/opt p50':>12} {'flight s':>8} {band_head} {'i,j / k kg':>14}")
    rows = [
        (
            f"fuel-optimal, {f:.2f} vertical",
            [r.fuel for r in sols],
            [r.time_of_flight for r in sols],
            [
                bands(r.states[:, 2], r.state_times, r.states[:, 6])
                + axis_split(r.thrust, np.diff(r.control_times, append=r.time_of_flight), r.fuel)
                for r in sols
            ],
        )
        for f, sols in solved.items()
    ]
    for spec in a.agents:
        built = build(spec)
        actor, label = built.actor, built.label
        ro = rollout(actor, a.episodes, a.seed, keep_trajectories=a.episodes)
        if not ro.landed.all():
            label += f" ({ro.landed.mean() * 100:.0f} % landed)"
        t = np.arange(max(len(p) for p in ro.trajectories)) * DT_S
        split = [
            bands(p[:, 2], t[: len(p)], p[:, 6])
            + axis_split(DEFAULT_ACTIONS.thrust(act), np.full(len(act), DT_S), p[0, 6] - p[-1, 6])
            for p, act in zip(ro.trajectories, ro.actions, strict=True)
        ]
        rows.append((label, ro.fuel_kg, ro.steps * DT_S, split))
    for label, fuel, flight, split in rows:
        med = np.median(np.array(split), axis=0)
        cells = " ".join(f"{med[k]:>6.1f} / {med[k + 1]:>5.1f}" for k in range(0, len(med), 2))
        print(
            f"{label[:28]:<28} {np.median(np.asarray(fuel) / optimum):>12.3f} "
            f"{np.median(flight):>8.1f} {cells}"
        )


if __name__ == "__main__":
    main()
