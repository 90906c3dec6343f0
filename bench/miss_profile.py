"""Where the nominal miss is made (issue 10's median miss <= 1 m, on every seed), in one run.

    python bench/miss_profile.py [--episodes 300] [--seed 0] [--agents SPEC ...]

Each agent (`pd-eval` specs: a policy file, `controller:NAME`, `layer:controller:NAME`) flies
the same nominal episodes. Printed per agent, side by side: the median lateral distance to the
pad and lateral speed as each flight first passes below each altitude gate, and the touchdown
miss. Then, for each agent that is not the teacher, how often its lateral (i, j) levels equal
the teacher's in the states it flies, by altitude band: a student that reaches the last metres
as close as its teacher but chooses other lateral levels there makes its miss in them.
"""

from __future__ import annotations

import argparse
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from pd_core.actions import DEFAULT_ACTIONS  # noqa: E402
from pd_core.episodes import Rollouts, rollout  # noqa: E402
from pd_core.runtime.build import build  # noqa: E402

GATES_M = (100.0, 20.0, 10.0, 5.0, 2.0, 1.0)
BANDS_M = ((0.0, 2.0), (2.0, 5.0), (5.0, 20.0), (20.0, 100.0), (100.0, 1e4))
TEACHER = "layer:controller:zemzev-vernier"


def at_gates(ro: Rollouts) -> np.ndarray:
    """(len(GATES_M), 2): median lateral distance (m) and speed (m/s) at each altitude gate."""
    out = np.zeros((len(GATES_M), 2))
    for g, h in enumerate(GATES_M):
        rows = [p[int(np.argmax(p[:, 2] < h))] for p in ro.trajectories]
        s = np.array(rows)
        out[g] = np.median(np.hypot(s[:, 0], s[:, 1])), np.median(np.hypot(s[:, 3], s[:, 4]))
    return out


def lateral_agreement(ro: Rollouts, teacher: object) -> list[float]:
    """Share of the steps, per altitude band, on which the teacher picks the same (i, j)."""
    states = np.concatenate([p[:-1] for p in ro.trajectories])
    mine = DEFAULT_ACTIONS.level_table[np.concatenate(ro.actions)][:, :2]
    theirs = DEFAULT_ACTIONS.level_table[teacher.act_batch(states)][:, :2]
    same = np.all(mine == theirs, axis=1)
    z = states[:, 2]
    return [float(same[(z >= lo) & (z < hi)].mean()) for lo, hi in BANDS_M]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--episodes", type=int, default=300, help="nominal episodes per agent")
    ap.add_argument("--seed", type=int, default=0, help="seed of episode 0")
    ap.add_argument(
        "--agents",
        nargs="+",
        default=["models/pd_dqn_robust.pt", TEACHER],
        help=f"pd-eval specs; the teacher for the agreement is {TEACHER}",
    )
    args = ap.parse_args(argv)
    if args.episodes < 1:
        ap.error("--episodes must be >= 1")
    teacher = build(TEACHER).actor
    head = " ".join(f"{f'<{h:g} m':>12}" for h in GATES_M)
    print(f"median lateral distance (m) / speed (m/s) on first passing below, {args.episodes} "
          f"nominal episodes, seed {args.seed}")  # fmt: skip
    print(f"{'agent':<36}{head}{'touchdown':>12}")
    agree = {}
    for spec in args.agents:
        actor = build(spec).actor
        ro = rollout(actor, args.episodes, args.seed, keep_trajectories=args.episodes)
        g = at_gates(ro)
        miss = float(np.median(np.hypot(ro.final_states[:, 0], ro.final_states[:, 1])))
        cells = " ".join(f"{r:6.2f}/{v:<5.2f}" for r, v in g)
        print(f"{spec[-36:]:<36}{cells}{miss:12.2f}")
        if spec != TEACHER:
            agree[spec] = lateral_agreement(ro, teacher)
    if agree:
        bands = " ".join(f"{f'{lo:g}-{hi:g} m':>12}" for lo, hi in BANDS_M)
        print(f"\nshare of steps whose lateral levels equal {TEACHER}'s, by altitude")
        print(f"{'agent':<36}{bands}")
        for spec, a in agree.items():
            print(f"{spec[-36:]:<36}" + " ".join(f"{x:12.3f}" for x in a))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
