"""Conversions between pd_core values and the messages pd_sim_node speaks (no logic here)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Vector3

from pd_core.sim import Command
from pd_interfaces.msg import EpisodeResult, LanderState, ThrustCommand

FRAME_ID = "landing_site"


def vec3(v: Sequence[float] | np.ndarray) -> Vector3:
    return Vector3(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def from_vec3(v: Vector3) -> list[float]:
    return [v.x, v.y, v.z]


def sim_time(t_s: float) -> Time:
    """Simulation time (s since the episode started) as a header stamp."""
    ns = round(t_s * 1e9)
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def state_msg(
    episode: int, step: int, time_s: float, state: np.ndarray, status: int
) -> LanderState:
    msg = LanderState(episode=episode, step=step, mass=float(state[6]), status=int(status))
    msg.header.stamp = sim_time(time_s)
    msg.header.frame_id = FRAME_ID
    msg.position = vec3(state[0:3])
    msg.velocity = vec3(state[3:6])
    return msg


def state_from_msg(msg: LanderState) -> np.ndarray:
    """The physical 7-vector [x, y, z, vx, vy, vz, m] of a LanderState."""
    return np.array([*from_vec3(msg.position), *from_vec3(msg.velocity), msg.mass], dtype=float)


def command_from_msg(msg: ThrustCommand) -> Command:
    return Command(int(msg.episode), int(msg.step), int(msg.action), tuple(from_vec3(msg.thrust)))


def result_msg(result: dict[str, Any]) -> EpisodeResult:
    """EpisodeResult of a `pd_core.sim.Simulator` result dict (stamp = time of flight)."""
    msg = EpisodeResult()
    msg.header.stamp = sim_time(result["time_of_flight"])
    msg.header.frame_id = FRAME_ID
    for key in ("episode", "steps", "rejected_commands", "missed_commands", "status"):
        setattr(msg, key, int(result[key]))
    for key in ("time_of_flight", "final_mass", "fuel"):
        setattr(msg, key, float(result[key]))
    for key in ("initial_position", "initial_velocity", "final_position", "final_velocity"):
        setattr(msg, key, vec3(result[key]))
    msg.landed = bool(result["landed"])
    msg.reason = str(result["reason"])
    return msg
