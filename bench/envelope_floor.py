"""Is <= 1.04x the fuel-optimal landing reachable by a teacher the runtime layer leaves alone?
(issue 32, stage 1; issue 68: with the braking limit that counts on the mass lost while
braking). The fuel-optimal OCP from the same nominal states, three ways:

    python bench/envelope_floor.py [--episodes 20] [--seed 0] [--margin 0.0 0.7] [--mass-loss]
        [--counted 1.0]

* unreserved: `ocp.solve(objective="fuel")`, RL limits (the reference of `pd-eval
  --fuel-optimal`);
* 10 % vertical reserve: the same with the vertical maximum at 0.9 x 13 kN
  (`bench/fuel_floor.py`: 1.031x). Printed beside it: how far its descent speed exceeds the
  runtime layer's braking limit v_max(z, m) = sqrt(0.5^2 + 2 z (0.9 x 13 kN / m - g)) (m/s, the
  worst step), and the share of its steps on which the layer would raise a 6.5 kN command
  (`pd_core.teachers.mpc.brake_limited`): the limit counts on 90 % of the thrust at the mass
  the lander has *now*, the 0.9 plan on the lighter mass it will have when it brakes;
* inside the envelope: the cheapest plan found that keeps descent speed <= v_max - margin at
  every step (`pd_core.ocp.fuel.envelope_fuel_plan`, 40 control points, LP passes and a search
  on t_f; a local optimum, so an upper bound on that floor), for each `--margin`.

v_max is `pd_core.envelope`'s, the law the layer compiles: at the mass now (every file before
issue 68), or with `--mass-loss` counting on the mass lost while braking
(`RulesConfig.brake_mass_loss`); `--counted` is the fraction of the engine's thrust the limit
counts on (1: nominal; 0.8: the weakest engine promised, `LatencyConfig.unmeasured_thrust`).
"""

from __future__ import annotations

import argparse
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from pd_core import ocp  # noqa: E402
from pd_core.config import (  # noqa: E402
    BRAKE_MARGIN,
    GRAVITY_MPS2,
    LAND_SPEED_MPS,
    RL_THRUST,
    ThrustLimits,
)
from pd_core.envelope import descent_limits  # noqa: E402
from pd_core.episodes import rollout  # noqa: E402
from pd_core.ocp.fuel import BrakeEnvelope, envelope_fuel_plan  # noqa: E402
from pd_core.ocp.lp import new_highs  # noqa: E402
from pd_core.teachers.mpc import brake_limited  # noqa: E402
from pd_core.teachers.registry import make_controller  # noqa: E402

T_MAX_N = float(RL_THRUST.max_n[2])


def reserve(f: float) -> ThrustLimits:
    """RL limits, every axis at fraction f (as the teacher's plans)."""
    return ThrustLimits(
        tuple(f * np.array(RL_THRUST.min_n)),  # type: ignore[arg-type]
        tuple(f * np.array(RL_THRUST.max_n)),  # type: ignore[arg-type]
    )


def excess(states: np.ndarray, mass_loss: bool, counted: float) -> tuple[float, float]:
    """(worst descent speed above the layer's limit m/s, share of steps where a 6.5 kN command
    would be raised) along states (n, 7), the limit counting on `counted` of the thrust."""
    z, vz, m = states[:, 2], states[:, 5], states[:, 6]
    g = -float(GRAVITY_MPS2[2])
    force = BRAKE_MARGIN * counted * T_MAX_N
    vmax, _ = descent_limits(z, m, force, LAND_SPEED_MPS, g, mass_loss)
    top = counted * T_MAX_N
    raised = [
        brake_limited(s, counted * T_MAX_N / 2, top, mass_loss=mass_loss) for s in states[:-1]
    ]
    return float((-vz - vmax).max()), float(np.mean(raised))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--episodes", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--fraction", type=float, default=0.9, help="plan limits (all axes)")
    ap.add_argument("--margin", type=float, nargs="+", default=[0.0, 0.7])
    ap.add_argument(
        "--mass-loss", action="store_true", help="the limit counts on the mass lost while braking"
    )
    ap.add_argument("--counted", type=float, default=1.0, help="thrust fraction counted on")
    ap.add_argument("--max-extra", type=float, default=15.0, help="t_f searched beyond, s")
    a = ap.parse_args(argv)
    starts = rollout(make_controller("zemzev"), a.episodes, a.seed).initial_states
    rows = []
    for s in starts:
        ref = ocp.solve(s[0:3], s[3:6], s[6], objective="fuel", limits=RL_THRUST)
        res = ocp.solve(s[0:3], s[3:6], s[6], objective="fuel", limits=reserve(a.fraction))
        worst, raised = excess(res.states, a.mass_loss, a.counted)
        pb = ocp.Problem(s[0:3], s[3:6], s[6], "fuel", 40, reserve(a.fraction))
        p0 = np.column_stack(
            [
                np.interp(np.linspace(0, 1, 40), np.linspace(0, 1, len(res.thrust)), c)
                for c in res.thrust.T
            ]
        )
        row = [ref.fuel, res.fuel / ref.fuel, worst, raised]
        for mg in a.margin:
            env = BrakeEnvelope(
                BRAKE_MARGIN, a.counted * T_MAX_N, LAND_SPEED_MPS, mg, 0.0, 1, mass_loss=a.mass_loss
            )
            out = envelope_fuel_plan(
                pb, p0, res.time_of_flight, env, new_highs(), 10, max_extra_s=a.max_extra
            )
            if out is None:
                row.append(np.nan)
                continue
            st, _ = pb.simulate(out[0], out[1])
            row.append((s[6] - st[-1, 6]) / ref.fuel)
        rows.append(row)
        print(" ".join(f"{v:8.3f}" for v in row), flush=True)
    r = np.array(rows)
    law = "counting on the mass lost while braking" if a.mass_loss else "at the mass now"
    print(f"the layer's braking limit {law}, counting on {a.counted:.2f} of the thrust")
    print(
        f"{len(r)} nominal states (seed {a.seed}): unreserved optimum {np.median(r[:, 0]):.1f} kg; "
        f"{a.fraction:.2f} reserve {np.median(r[:, 1]):.3f}x, above the layer's limit by "
        f"{np.median(r[:, 2]):.2f} m/s (worst step, median), a 6.5 kN command raised on "
        f"{100 * np.median(r[:, 3]):.0f} % of its steps"
    )
    for k, mg in enumerate(a.margin):
        col = r[:, 4 + k]
        print(
            f"inside the layer's limit - {mg:.1f} m/s: median {np.nanmedian(col):.3f}x, "
            f"min {np.nanmin(col):.3f}, max {np.nanmax(col):.3f} "
            f"({int(np.isnan(col).sum())} not found)"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
