"""Does an agent brake a lateral slide in the last metres? One fixed grid of states, any agents.

The shipped student's `standard` failures are lateral slides onto the pad: 1.8-2.9 m/s of
horizontal speed at touchdown, the network holding zero horizontal thrust in its last seconds
(`bench/touchdown_anatomy.py`). Eq. 12 lands only below 2 m/s in all, so from these states
braking is what saves the landing. This bench asks every agent the same question on a fixed
grid: the lander 1.5-8 m up, descending as the braking limit lets it, 0-4 m short of the pad
and sliding towards or across it at 1.5-3 m/s (x only; 1750 kg). It prints the share of states
on which the agent's horizontal command opposes the slide, per altitude, and each agent's
horizontal level per state.

    python bench/slide_probe.py [AGENT ...]

An AGENT is a policy file (its network alone: below 5 m no rule of the runtime layer acts on
the horizontal axes), or `controller:NAME` (`zemzev-vernier`, `mpc-fuel-reserve`, ...): a
controller that plans answers from each state alone, with a cold solve (`propose` of a fresh
`MPCController`: no plan held). Default: the shipped policy, its teacher and ZEM/ZEV-vernier. A
few seconds; no campaign is flown.
"""

from __future__ import annotations

import argparse

import numpy as np

from pd_core.actions import DEFAULT_ACTIONS
from pd_core.runtime.build import build
from pd_core.runtime.policy_file import SHIPPED_POLICY

ALTITUDES_M = ((1.5, -1.5), (2.8, -2.8), (4.0, -3.0), (8.0, -4.0))  # (z, vz) pairs
SHORT_M = (-4.0, -3.0, -2.0, -1.0, 0.0)  # x: the pad lies ahead of a lander sliding at +vx
SLIDE_MPS = (1.5, 2.0, 2.5, 3.0)
MASS_KG = 1750.0


def probe_states() -> np.ndarray:
    """(80, 7) states: every altitude, offset and slide speed of the grid."""
    rows = [
        [x, 0.0, z, vx, 0.0, vz, MASS_KG]
        for z, vz in ALTITUDES_M
        for x in SHORT_M
        for vx in SLIDE_MPS
    ]
    return np.array(rows)


def x_levels(spec: str, states: np.ndarray) -> np.ndarray:
    """The agent's horizontal (x) thrust level on each state."""
    # the network or controller alone, each state on its own (a fresh MPC teacher plans each
    # from scratch: `propose` on no plans)
    actions = build(spec, as_runtime=True).runtime.actor.propose(states)
    return DEFAULT_ACTIONS.level_table[np.asarray(actions, dtype=np.int64)][:, 0]


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    default = [str(SHIPPED_POLICY), "controller:mpc-fuel-reserve", "controller:zemzev-vernier"]
    ap.add_argument("agents", nargs="*", default=default, help="policy files or controller:NAME")
    a = ap.parse_args()
    states = probe_states()
    zero = DEFAULT_ACTIONS.n_per_axis[0] // 2  # the middle level: no horizontal thrust
    print(f"{len(states)} sliding states; x level {zero} is zero thrust, below it brakes")
    header = "".join(f"{f'z {z:g} m':>9}" for z, _ in ALTITUDES_M)
    print(f"{'agent':<40}{'brakes':>8}{header}")
    per_state = {}
    for spec in a.agents:
        lv = x_levels(spec, states)
        brake = lv < zero
        by_z = "".join(f"{brake[states[:, 2] == z].mean():>9.0%}" for z, _ in ALTITUDES_M)
        print(f"{spec:<40}{brake.mean():>8.0%}{by_z}")
        per_state[spec] = lv
    print("\nx level per state (rows: altitude; x from -4 to 0 m, each at 1.5, 2, 2.5, 3 m/s):")
    for spec, lv in per_state.items():
        print(spec)
        for z, _ in ALTITUDES_M:
            print(f"  z {z:>3g} m: " + " ".join(map(str, lv[states[:, 2] == z])))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
