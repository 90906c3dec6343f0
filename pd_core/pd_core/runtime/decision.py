"""`Decision`: what the runtime layer did on one step, and who decided the action flown.

The sources are numbered as in `pd_interfaces/msg/GuidanceStatus` (SOURCE_*), so a recorded bag
and the node's statistics count the same thing: a step whose action differs from the network's
own counts for the rule that changed it last; a rule that fired without changing the action does
not count.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

NETWORK, BRAKE, GUARD, HANDOVER = 0, 1, 2, 3
SOURCES = ("network", "brake", "guard", "handover")
"""name of each source, by number"""
LIMITS = ("none", "descent", "descent-mass-loss", "touchdown")
"""name of each braking limit (`pd_core.envelope.brake_fires`), by number: none fired; the
descent speed at the mass now; the descent speed counting on the mass lost while braking; the
touchdown speed of a step that ends on the ground"""


def changed_count(counts: Mapping[str, int]) -> int:
    """Steps some rule decided (every source but the network) among `counts` (source -> steps)."""
    return sum(v for k, v in counts.items() if k != SOURCES[NETWORK])


def describe_counts(counts: Mapping[str, int]) -> str:
    """'changed C of N actions (brake b, guard g, handover h)' for steps counted by source."""
    rules = ", ".join(f"{k} {v}" for k, v in counts.items() if k != SOURCES[NETWORK])
    return f"changed {changed_count(counts)} of {sum(counts.values())} actions ({rules})"


@dataclass(frozen=True)
class Decision:
    """One step of one lander."""

    action: int
    """the action flown"""
    proposed: int
    """the network's (or controller's) own action on the state decided on"""
    source: str
    """who decided `action`: one of SOURCES"""
    delay_steps: int
    """actuation delay identified in flight (0.2 s steps)"""
    thrust_gain_bound: float
    """delivered / commanded vertical thrust the braking limit counts on (1: nominal)"""
    nav_filter_engaged: bool
    """the state decided on is the navigation filter's estimate (else the observation)"""
    brake_limit: str = LIMITS[0]
    """the braking limit that fired on the command (one of LIMITS; it fires whether or not it
    changed the action: `source` says who decided)"""

    @property
    def changed(self) -> bool:
        """True where the runtime layer changed the network's action."""
        return self.action != self.proposed


@dataclass
class Decisions:
    """Decisions of a batch of landers (arrays over rows)."""

    action: np.ndarray
    proposed: np.ndarray
    source: np.ndarray
    """(B,) uint8 source numbers (NETWORK, BRAKE, GUARD, HANDOVER)"""
    delay_steps: np.ndarray
    thrust_gain_bound: np.ndarray
    nav_filter_engaged: np.ndarray
    brake_limit: np.ndarray
    """(B,) uint8 limit numbers (LIMITS)"""

    def __getitem__(self, i: int) -> Decision:
        return Decision(
            int(self.action[i]),
            int(self.proposed[i]),
            SOURCES[int(self.source[i])],
            int(self.delay_steps[i]),
            float(self.thrust_gain_bound[i]),
            bool(self.nav_filter_engaged[i]),
            LIMITS[int(self.brake_limit[i])],
        )
