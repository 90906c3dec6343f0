"""pd_core: physics, optimal control and learning for powered descent. Imports no rclpy.

`pd_core.load_policy(path)` returns the `pd_core.runtime.Runtime` that flies a policy file (torch
is imported only to read its weights).
"""

from __future__ import annotations

from typing import Any

__version__ = "0.3.0"


def load_policy(path: Any, shield: str = "file") -> Any:
    """The runtime that flies a policy file; see `pd_core.runtime.policy_file.load_policy`."""
    from pd_core.runtime.policy_file import load_policy as _load

    return _load(path, shield=shield)
