"""Messages <-> numpy, in one place (no logic beyond copying fields).

The physical state is the 7-vector [x, y, z, vx, vy, vz, m] (m, m/s, kg) of pd_core; thrust is a
3-vector in N; stamps are simulation time (s since the episode started).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Vector3

from pd_core.commands import Command
from pd_core.runtime.decision import SOURCES, Decision
from pd_interfaces.msg import EpisodeResult, GuidanceStatus, LanderState, ThrustCommand
from pd_interfaces.srv import ComputeTrajectory, ResetEpisode

FRAME_ID = "landing_site"


def vec3(v: Sequence[float] | np.ndarray) -> Vector3:
    return Vector3(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def from_vec3(v: Vector3) -> np.ndarray:
    return np.array([v.x, v.y, v.z], dtype=float)


def vec3_list(rows: np.ndarray) -> list[Vector3]:
    return [vec3(r) for r in np.asarray(rows, dtype=float).reshape(-1, 3)]


def from_vec3_list(vs: Sequence[Vector3]) -> np.ndarray:
    return np.array([[v.x, v.y, v.z] for v in vs], dtype=float).reshape(-1, 3)


def sim_time(t_s: float) -> Time:
    """Simulation time (s since the episode started) as a header stamp."""
    ns = round(t_s * 1e9)
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def state_vector(position: Vector3, velocity: Vector3, mass: float) -> np.ndarray:
    return np.array([*from_vec3(position), *from_vec3(velocity), mass], dtype=float)


# ---------------------------------------------------------------------------------- topics
def state_msg(
    episode: int, step: int, time_s: float, state: np.ndarray, status: int
) -> LanderState:
    msg = LanderState(episode=episode, step=step, mass=float(state[6]), status=int(status))
    msg.header.stamp = sim_time(time_s)
    msg.header.frame_id = FRAME_ID
    msg.position = vec3(state[0:3])
    msg.velocity = vec3(state[3:6])
    return msg


def state_from_msg(msg: Any) -> np.ndarray:
    """The physical 7-vector of a LanderState (or anything with position, velocity, mass)."""
    return state_vector(msg.position, msg.velocity, msg.mass)


def command_msg(state: LanderState, action: int, thrust_n: np.ndarray) -> ThrustCommand:
    """The command answering `state` (same episode, step, stamp and frame)."""
    cmd = ThrustCommand(episode=state.episode, step=state.step, action=int(action))
    cmd.header.stamp = state.header.stamp
    cmd.header.frame_id = state.header.frame_id
    cmd.thrust = vec3(thrust_n)
    return cmd


def guidance_msg(state: LanderState, d: Decision, decision_time_s: float) -> GuidanceStatus:
    """The GuidanceStatus of the command answering `state` (same header, episode and step)."""
    msg = GuidanceStatus(
        episode=state.episode,
        step=state.step,
        action=int(d.action),
        proposed_action=int(d.proposed),
        source=SOURCES.index(d.source),
        delay_steps=int(d.delay_steps),
        thrust_gain_bound=float(d.thrust_gain_bound),
        nav_filter_engaged=bool(d.nav_filter_engaged),
        decision_time_s=float(decision_time_s),
    )
    msg.header.stamp = state.header.stamp
    msg.header.frame_id = state.header.frame_id
    return msg


def command_from_msg(msg: ThrustCommand, source: str = "") -> Command:
    """`source`: the publishing node's name, when the receiver resolved it."""
    t = from_vec3(msg.thrust)
    thrust = tuple(float(v) for v in t)
    return Command(int(msg.episode), int(msg.step), int(msg.action), thrust, source)


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


def final_state(result: EpisodeResult) -> np.ndarray:
    return state_vector(result.final_position, result.final_velocity, result.final_mass)


# ---------------------------------------------------------------------------------- services
def reset_request(state: np.ndarray | None = None, seed: int = -1) -> ResetEpisode.Request:
    """/sim/reset request: from `state` (7,), or Table 3 sampled (None); seed -1 = RNG goes on."""
    req = ResetEpisode.Request(use_initial_state=state is not None, seed=int(seed))
    if state is not None:
        req.position, req.velocity, req.mass = vec3(state[0:3]), vec3(state[3:6]), float(state[6])
    return req


def ocp_request(state: np.ndarray, **fields: Any) -> ComputeTrajectory.Request:
    """/ocp/compute_trajectory request from the physical state; `fields` set the rest."""
    req = ComputeTrajectory.Request(mass=float(state[6]), **fields)
    req.position, req.velocity = vec3(state[0:3]), vec3(state[3:6])
    return req


def fill_ocp_response(res: Any, response: ComputeTrajectory.Response) -> None:
    """Copy a `pd_core.ocp.OCPResult` into the response (trajectory only if there is one)."""
    response.success = bool(res.success)
    response.message = str(res.message)
    response.solve_time = float(res.solve_time)
    for key in ("time_of_flight", "fuel", "cost"):
        v = float(getattr(res, key))
        setattr(response, key, v if math.isfinite(v) else 0.0)
    if len(res.states):
        response.control_times = [float(t) for t in res.control_times]
        response.thrust = vec3_list(res.thrust)
        response.state_times = [float(t) for t in res.state_times]
        response.positions = vec3_list(res.states[:, 0:3])
        response.velocities = vec3_list(res.states[:, 3:6])
        response.masses = [float(m) for m in res.states[:, 6]]


def ocp_trajectory(response: ComputeTrajectory.Response) -> dict[str, np.ndarray]:
    """{"state_times", "states" (N, 7), "control_times", "thrust" (M, 3)} of a response."""
    states = np.column_stack(
        [
            from_vec3_list(response.positions),
            from_vec3_list(response.velocities),
            np.asarray(response.masses, dtype=float),
        ]
    )
    return {
        "state_times": np.asarray(response.state_times, dtype=float),
        "states": states.reshape(-1, 7),
        "control_times": np.asarray(response.control_times, dtype=float),
        "thrust": from_vec3_list(response.thrust),
    }
