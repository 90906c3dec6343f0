"""Controllers by name: `pd-eval --controller NAME`, `controller:NAME` specs and the policy node.

`mpc-fuel` and `mpc-energy` are the receding-horizon optimal-control teacher
(`pd_core.teachers.mpc`) with the fuel or the energy (Eq. 4) objective, and ZEM/ZEV as its
fallback near the pad. `mpc-fuel-reserve` is the fuel teacher that keeps the runtime layer's
vertical reserve (`pd_core.teachers.mpc.reserve_controller`, issue 32).
"""

from __future__ import annotations

from collections.abc import Callable

from pd_core.teachers.mpc import MPCController, mpc_controller, reserve_controller
from pd_core.teachers.zemzev import VERNIER_PARAMS, ZemZevController


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
