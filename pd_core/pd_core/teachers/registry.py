"""Controllers by name: `pd-eval --controller NAME`, `controller:NAME` specs and the policy node.

`mpc-fuel` and `mpc-energy` are the receding-horizon optimal-control teacher
(`pd_core.teachers.mpc`) with the fuel or the energy (Eq. 4) objective, and ZEM/ZEV as its
fallback near the pad. `mpc-fuel-reserve` is the fuel teacher that keeps the runtime layer's
vertical reserve (`reserve_controller`, issue 32).
"""

from __future__ import annotations

from collections.abc import Callable

from pd_core import ocp
from pd_core.teachers.mpc import Actor, MPCController, MPCParams
from pd_core.teachers.zemzev import VERNIER_PARAMS, ZemZevController


def mpc_controller(objective: str, fallback: Actor) -> MPCController:
    """The teacher with the RL action set (Sec. 4.1) and the rounding measured best for its
    objective (8 nominal episodes, bench/mpc_speed.py): the energy plans are smooth, and the
    reference-carrying Eq. 5 tracks them (fuel 1.16x the fuel optimum, against 1.54x when
    Eq. 6 is reset every step); the bang-bang fuel plans sit at their thrust limit, where the
    carried reference lets the lander fall behind (crashes), so "eq5-replan" (1.19x, lands)."""
    if objective not in ocp.OBJECTIVES:
        raise ValueError(f"objective must be one of {ocp.OBJECTIVES}, got {objective!r}")
    rounding = "eq5" if objective == "energy" else "eq5-replan"
    return MPCController(MPCParams(objective=objective, rounding=rounding), fallback)


RESERVE_PARAMS = MPCParams(
    objective="fuel",
    rounding="nearest",
    keep_brake_limit=True,
    gate_altitude_m=0.5,
    terminal_time_s=2.0,
    lateral_settle_s=2.0,
)


def reserve_controller(fallback: Actor, params: MPCParams = RESERVE_PARAMS) -> MPCController:
    """`mpc-fuel-reserve` (issue 32): the fuel teacher flying its own plans within the runtime
    layer's vertical reserve. Measured on nominal episodes behind the layer
    (bench/mpc_diagnose.py, docs/experiments/2026-11-26-fuel-optimal-teacher.md):

    * plans on 90 % of every axis's thrust (the vertical reserve the braking limit counts on);
    * quantises to the nearest level ("eq5-replan" rounds every braking step up to full
      thrust, 1.28x against 1.11x), then raises the vertical level where the layer's braking
      limit would (`keep_brake_limit`): the layer and the teacher agree, and the layer changes
      under 1 % of its steps (32 % for `mpc-fuel`);
    * plans end at rest 0.5 m above the pad (2 m: the fallback's slow final descent costs
      ~4 % of the fuel), and the t_f search stays (without it 1.22x, 80 % landed);
    * the fallback lands the last 2 s of the plan (1 s: 6 of 300 nominal episodes land with
      the lateral speed the plan still had to brake, 2.2-3.4 m/s; 2 s: 1 of 300, 0.6 % more
      fuel). A lateral reserve (0.7 or 0.8 of the lateral thrust) did not help (3-4 of 300);
    * the plans hold the horizontal thrust at 0 over their last 1-2 s (`lateral_settle_s`):
      the horizontal motion ends before the fallback lands the rest, where the fuel optimum
      braked it last (docs/experiments/2026-11-26-ocp-student.md).
    """
    ctl = MPCController(params, fallback)
    ctl.name = "mpc-fuel-reserve"
    return ctl


def _mpc(objective: str) -> Callable[[], MPCController]:
    return lambda: mpc_controller(objective, fallback=ZemZevController())


# name -> factory: `pd-eval --controller NAME`, `controller:NAME` specs and the policy node
FACTORIES: dict[str, Callable[[], ZemZevController | MPCController]] = {
    "zemzev": ZemZevController,
    "zemzev-vernier": lambda: ZemZevController(VERNIER_PARAMS),
    "mpc-fuel": _mpc("fuel"),
    "mpc-energy": _mpc("energy"),
    "mpc-fuel-reserve": lambda: reserve_controller(ZemZevController(VERNIER_PARAMS)),
}
CONTROLLERS = tuple(FACTORIES)


def make_controller(name: str) -> ZemZevController | MPCController:
    """A fresh controller by name (MPC controllers keep plans: one per campaign or episode)."""
    if name not in FACTORIES:
        raise ValueError(f"unknown controller {name!r}; choose from {', '.join(CONTROLLERS)}")
    return FACTORIES[name]()
