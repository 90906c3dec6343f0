"""pd_core: physics, optimal control and learning for powered descent. Imports no rclpy.

`pd_core.load_policy(path)` returns the `pd_core.runtime.Runtime` that flies a policy file (torch
is imported only to read its weights).
"""

from __future__ import annotations

from typing import Any

from pd_core.deprecation import renamed_argument

__version__ = "0.3.0"


def load_policy(path: Any, layer: str = "file", *, shield: str | None = None) -> Any:
    """The runtime that flies a policy file; see `pd_core.runtime.policy_file.load_policy`
    (`shield`: the old name of `layer`, deprecated: it warns)."""
    from pd_core.runtime.policy_file import load_policy as _load

    return _load(path, renamed_argument("load_policy", "shield", shield, "layer", layer, "file"))
