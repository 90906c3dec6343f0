"""Controllers by name: `pd-eval --controller NAME`, `controller:NAME` specs and the policy node.

`mpc-fuel` and `mpc-energy` are the receding-horizon optimal-control teacher
(`pd_core.teachers.mpc`) with the fuel or the energy (Eq. 4) objective, and ZEM/ZEV as its
fallback near the pad. `mpc-fuel-reserve` is the fuel teacher that keeps the runtime layer's
vertical reserve (`reserve_controller`, issue 32); `mpc-fuel-reserve-state`, the training
recipe's teacher, is the same teacher handing over to its fallback on the state's clock.
`mpc-fuel-reserve-state-ml` (issue 68) is that teacher quantising within the braking limit that
counts on the mass lost while braking, on the vertical thrust fraction its runtime layer counts
on (`RESERVE_STATE_ML_PARAMS`); without a layer it counts on full thrust.
`mpc-fuel-reserve-state-ml-plan` also plans inside that limit (`RESERVE_STATE_ML_PLAN_PARAMS`);
`mpc-fuel-reserve-state-lf` keeps the limit at the mass now on that fraction.

Importing the registry loads no solver: the teachers' settings are plain dataclasses
(`pd_core.teachers.mpc_params`), and the teacher (`pd_core.teachers.mpc`, which imports the OCP
solvers) is imported when an MPC controller is built. A ZEM/ZEV controller needs numpy only.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING

from pd_core.teachers.mpc_params import MPCParams
from pd_core.teachers.zemzev import VERNIER_HOLD_PARAMS, VERNIER_PARAMS, ZemZevController

if TYPE_CHECKING:
    from pd_core.teachers.mpc import Actor, MPCController


def mpc_controller(objective: str, fallback: Actor) -> MPCController:
    """The teacher with the RL action set (Sec. 4.1) and the rounding chosen per objective
    (measured in bench/mpc_speed.py, docs/experiments/2026-11-26-fuel-optimal-teacher.md): the
    energy plans are smooth and the reference-carrying Eq. 5 ("eq5") tracks them; the bang-bang
    fuel plans sit at their thrust limit, where a carried reference lets the lander fall
    behind, so the fuel teacher takes its reference from the plan just made ("eq5-replan")."""
    # optional heavy dependency: the teacher imports the OCP solvers, loaded when one is built
    from pd_core import ocp
    from pd_core.teachers.mpc import MPCController

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
# `mpc-fuel-reserve-state`, the recipe's teacher since 2026-12-02: the fallback lands once the
# state's time to rest at the gate is under 2 s (`MPCParams.handover_from_state`), not the
# plan's time-to-go, so that a student, which sees the state and not the plan, can learn when
# the end-game starts (docs/experiments/2026-12-02-state-handover.md).
RESERVE_STATE_PARAMS = replace(RESERVE_PARAMS, handover_from_state=True)
# `mpc-fuel-reserve-state-ml` (issue 68, item 2): the same, keeping the braking limit that counts
# on the mass lost while braking (`MPCParams.brake_mass_loss`, the layer's
# `RulesConfig.brake_mass_loss`) on the vertical thrust fraction the layer counts on this step
# (`MPCParams.layer_thrust_fraction`: the identified gain, or `unmeasured_thrust` until measured).
# Fly it behind a layer with the same settings, e.g.
# `set:brake_mass_loss=1,unmeasured_thrust=0.8:layer:controller:mpc-fuel-reserve-state-ml`
# (docs/experiments/2026-12-04-teacher-inside-the-new-limit.md).
RESERVE_STATE_ML_PARAMS = replace(
    RESERVE_STATE_PARAMS, brake_mass_loss=True, layer_thrust_fraction=True
)
# `mpc-fuel-reserve-state-lf`: the braking limit at the mass now (as every file before issue 68)
# on the fraction the layer counts on; fly it behind e.g. `set:unmeasured_thrust=0.8:` (the
# ablation of the mass-loss limit, docs/experiments/2026-12-05-adapt-student.md)
RESERVE_STATE_LF_PARAMS = replace(RESERVE_STATE_PARAMS, layer_thrust_fraction=True)
# `mpc-fuel-reserve-state-ml-plan`: the same whose fuel plans also keep 0.35 m/s inside that
# limit (`MPCParams.plan_brake_margin_mps`; the floor's middle margin, chosen before flying it),
# with 3 LP passes per warm re-plan (the envelope's rows are linearised at the shifted plan: with
# one pass the flights cost 1.41x, with three 1.07x; docs/experiments/
# 2026-12-04-teacher-inside-the-new-limit.md)
RESERVE_STATE_ML_PLAN_PARAMS = replace(
    RESERVE_STATE_ML_PARAMS, plan_brake_margin_mps=0.35, passes=3
)


def reserve_controller(
    fallback: Actor, params: MPCParams = RESERVE_PARAMS, name: str = "mpc-fuel-reserve"
) -> MPCController:
    """`mpc-fuel-reserve` (issue 32): the fuel teacher flying its own plans within the runtime
    layer's vertical reserve. Each choice below was measured on nominal episodes behind the
    layer (bench/mpc_diagnose.py; figures in docs/experiments/2026-11-26-fuel-optimal-teacher.md
    and 2026-11-26-ocp-student.md):

    * plans on 90 % of every axis's thrust (the vertical reserve the braking limit counts on);
    * quantises to the nearest level ("eq5-replan" rounds every braking step up to full thrust),
      then raises the vertical level where the layer's braking limit would
      (`keep_brake_limit`), so the layer and the teacher agree on nearly every step;
    * plans end at rest 0.5 m above the pad (at 2 m the fallback's slow final descent costs
      fuel), and the t_f search stays (without it the plans drift from their optimum);
    * the fallback lands the last 2 s of the plan (with 1 s, some landers touch down with the
      lateral speed the plan still had to brake);
    * the plans hold the horizontal thrust at 0 over their last 1-2 s (`lateral_settle_s`):
      the horizontal motion ends before the fallback lands the rest, where the fuel optimum
      braked it last.
    """
    from pd_core.teachers.mpc import MPCController  # optional heavy dependency (the solvers)

    ctl = MPCController(params, fallback)
    ctl.name = name
    return ctl


def _mpc(objective: str) -> Callable[[], MPCController]:
    return lambda: mpc_controller(objective, fallback=ZemZevController())


# name -> factory: `pd-eval --controller NAME`, `controller:NAME` specs and the policy node
FACTORIES: dict[str, Callable[[], ZemZevController | MPCController]] = {
    "zemzev": ZemZevController,
    "zemzev-vernier": lambda: ZemZevController(VERNIER_PARAMS),
    "zemzev-vernier-hold": lambda: ZemZevController(VERNIER_HOLD_PARAMS),
    "mpc-fuel": _mpc("fuel"),
    "mpc-energy": _mpc("energy"),
    "mpc-fuel-reserve": lambda: reserve_controller(ZemZevController(VERNIER_PARAMS)),
    "mpc-fuel-reserve-state": lambda: reserve_controller(
        ZemZevController(VERNIER_PARAMS), RESERVE_STATE_PARAMS, "mpc-fuel-reserve-state"
    ),
    "mpc-fuel-reserve-state-ml": lambda: reserve_controller(
        ZemZevController(VERNIER_PARAMS), RESERVE_STATE_ML_PARAMS, "mpc-fuel-reserve-state-ml"
    ),
    "mpc-fuel-reserve-state-lf": lambda: reserve_controller(
        ZemZevController(VERNIER_PARAMS), RESERVE_STATE_LF_PARAMS, "mpc-fuel-reserve-state-lf"
    ),
    # `mpc-fuel-reserve-state-lf` whose fallback holds the pad below the believed ground
    "mpc-fuel-reserve-state-lf-hold": lambda: reserve_controller(
        ZemZevController(VERNIER_HOLD_PARAMS),
        RESERVE_STATE_LF_PARAMS,
        "mpc-fuel-reserve-state-lf-hold",
    ),
    "mpc-fuel-reserve-state-ml-plan": lambda: reserve_controller(
        ZemZevController(VERNIER_PARAMS),
        RESERVE_STATE_ML_PLAN_PARAMS,
        "mpc-fuel-reserve-state-ml-plan",
    ),
}
CONTROLLERS = tuple(FACTORIES)


def make_controller(name: str) -> ZemZevController | MPCController:
    """A fresh controller by name; ValueError naming the known ones if there is none. MPC
    controllers keep the plans of the episodes in flight (`begin_episode` forgets them)."""
    if name not in FACTORIES:
        raise ValueError(f"unknown controller {name!r}; choose from {', '.join(CONTROLLERS)}")
    return FACTORIES[name]()
