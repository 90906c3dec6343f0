"""How fast does the runtime layer find an engine that weakens in flight? (issue 68)

    python bench/late_engine_probe.py [SPEC] [--episodes 200] [--seed 68000000]
        [--dispersions data/beyond.yaml] [--scenario engine80-100-late]

Flies `--episodes` episodes of a scenario with a thrust factor and an onset
(`Dispersions.thrust_factor_onset_s`) with an agent behind its runtime layer (a `pd-eval` spec,
default the shipped file), and prints, for the failed and the landed episodes apart: the factor,
the onset time, the altitude and vertical speed there, and how long after the onset the
fraction of vertical thrust the braking limit counts on (`Decision.thrust_gain_bound`) first
comes within `--tolerance` of the true factor (never: counted as such), and how many were
already lost at the onset whatever any controller did next: descending faster than the full
delivered thrust (the factor x 13 kN, vertical, no margin) can brake to the success speed (2 m/s)
by the pad, counting on the mass lost while braking (`pd_core.envelope`). That bound is physics,
not the layer's rule: it is the most any policy could do from the state it reached.
"""

from __future__ import annotations

import argparse
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from pd_core.config import DT_S, GRAVITY_MPS2, RL_THRUST  # noqa: E402
from pd_core.dispersions import load_scenarios  # noqa: E402
from pd_core.envelope import max_descent_speed_mass_loss_mps  # noqa: E402
from pd_core.runtime.build import build  # noqa: E402
from pd_core.runtime.layer import Runtime  # noqa: E402
from pd_core.runtime.policy_file import SHIPPED_POLICY  # noqa: E402
from pd_core.vector_env import make_vector_env  # noqa: E402


def lost_at_onset(at_onset: np.ndarray, factor: np.ndarray) -> np.ndarray:
    """(n,) True where the state at the onset (altitude m, vertical speed m/s, mass kg; NaN: no
    onset flown) descends faster than the factor's full vertical thrust can brake to 2 m/s."""
    g = -float(GRAVITY_MPS2[2])
    out = np.zeros(len(factor), dtype=bool)
    for i, (z, vz, m) in enumerate(at_onset):
        if np.isnan(z):
            continue
        force = float(factor[i]) * float(RL_THRUST.max_n[2])
        out[i] = -vz > max_descent_speed_mass_loss_mps(float(z), float(m), force, 2.0, g)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("spec", nargs="?", default=str(SHIPPED_POLICY))
    ap.add_argument("--episodes", type=int, default=200)
    ap.add_argument("--seed", type=int, default=68_000_000)
    ap.add_argument("--dispersions", default="data/beyond.yaml")
    ap.add_argument("--scenario", default="engine80-100-late")
    ap.add_argument("--tolerance", type=float, default=0.03)
    a = ap.parse_args(argv)
    (d,) = [s for s in load_scenarios(a.dispersions) if s.name == a.scenario]
    if d.thrust_factor is None:
        raise SystemExit(f"{a.scenario}: no thrust factor")
    built = build(a.spec)
    rt, label = built.actor, built.label
    if not isinstance(rt, Runtime):
        raise SystemExit(f"{a.spec}: not behind a runtime layer")
    n = a.episodes
    env = make_vector_env(n, autoreset=False, dispersions=d)
    _, info = env.reset(seed=a.seed)
    rt.begin_episodes(n)
    sd = env.state_dict()
    factor, onset = sd["thrust_factor"], sd["thrust_onset_step"]
    counted = np.full((n, env.max_steps + 1), np.nan)
    at_onset = np.full((n, 3), np.nan)
    landed = np.zeros(n, dtype=bool)
    actions = np.zeros(n, dtype=np.int64)
    active, k = env.active, 0
    while active.any():
        rows = np.flatnonzero(active)
        got, dec = rt.step_rows(info["observed_state"][active], rows)
        counted[rows, k] = dec.thrust_gain_bound
        hit = rows[onset[rows] == k]
        at_onset[hit] = env.states[hit][:, [2, 5, 6]]
        actions[active] = got
        _, _, _, _, info = env.step(actions)
        landed |= info["landed"]
        active, k = info["active"], k + 1
    lost = lost_at_onset(at_onset, factor)
    print(f"{label}, {a.scenario}: {n} episodes, seed {a.seed}, landed {landed.mean():.1%}")
    for name, sel in (("failed", ~landed), ("landed", landed)):
        idx = np.flatnonzero(sel)
        if not len(idx):
            continue
        lag = []
        for j in idx:
            near = np.flatnonzero(counted[j, onset[j] :] <= factor[j] + a.tolerance)
            lag.append(near[0] * DT_S if len(near) else np.inf)
        lag = np.array(lag)
        found = lag[np.isfinite(lag)]
        print(
            f"  {name} {len(idx)}: factor {np.median(factor[idx]):.3f}, onset "
            f"{np.median(onset[idx]) * DT_S:.1f} s at {np.nanmedian(at_onset[idx, 0]):.0f} m and "
            f"{np.nanmedian(at_onset[idx, 1]):.1f} m/s (medians); counted within "
            f"{a.tolerance} of the factor after {np.median(found) if len(found) else np.nan:.1f} s "
            f"median where it was, never in {int(np.isinf(lag).sum())}; beyond the full-thrust "
            f"bound at the onset {int(lost[idx].sum())}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
