"""What flies: a network (or controller) behind the runtime layer (`layer.Runtime`), its typed
config (`config.RuntimeConfig`, pinned whole in the policy file), the per-step record
(`decision.Decision`), the policy files (`policy_file`) and the one way to build what flies from
a file, the shipped one or a controller (`pd_core.runtime.build.build`). Imports numpy and numba
(the compiled per-lander arithmetic, `kernels*.py`), no solver and no Gymnasium; torch only reads
a weights file in `load_policy`."""

from pd_core.runtime.config import RuntimeConfig
from pd_core.runtime.decision import SOURCES, Decision
from pd_core.runtime.layer import Runtime
from pd_core.runtime.policy_file import PolicyLoadError, load_policy, save_policy

__all__ = [
    "SOURCES",
    "Decision",
    "PolicyLoadError",
    "Runtime",
    "RuntimeConfig",
    "load_policy",
    "save_policy",
]
