"""A thrust command as the simulator receives it (numpy-free, ROS-free: shared by the simulator,
the ROS message conversion and the tools)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Command:
    """A thrust command as received: the (episode, step) it answers, its action and thrust (N)."""

    episode: int
    step: int
    action: int
    thrust_n: tuple[float, float, float]
    source: str = ""  # name of the publishing node ("" when unknown or not asked for)
    lander_id: str = ""  # the lander whose state it answers ("" = unaddressed, any lander)
