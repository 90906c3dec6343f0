"""pd_core: physics, optimal control and learning for powered descent. Imports no rclpy.

`pd_core.load_policy(path)` loads a trained policy (torch is imported only when it is called).
"""

from __future__ import annotations

from typing import Any

__version__ = "0.1.0"


def load_policy(path: Any, shield: str = "file") -> Any:
    """Load a trained DQN policy file; see `pd_core.policy.load_policy`."""
    from pd_core.policy import load_policy as _load

    return _load(path, shield=shield)
