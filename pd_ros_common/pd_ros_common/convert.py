"""Messages <-> numpy, in one place (no logic beyond copying fields).

The physical state is the 7-vector [x, y, z, vx, vy, vz, m] (m, m/s, kg) of pd_core; thrust is a
3-vector in N; stamps of the stack's own messages are simulation time (s since the episode
started). A command, its guidance status and an episode result carry the `lander_id` of the
simulator run they belong to (the policy echoes the id of the state it answers). The viewer types
(nav_msgs Odometry and Path, rosgraph_msgs Clock) are stamped with the time the caller gives: the
continuous simulation clock in lockstep, the node's clock in real time.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, Pose, PoseStamped, Quaternion, Vector3
from nav_msgs.msg import Odometry, Path
from rosgraph_msgs.msg import Clock

from pd_core.commands import Command
from pd_core.runtime.decision import SOURCES, Decision
from pd_interfaces.msg import EpisodeResult, GuidanceStatus, LanderState, ThrustCommand
from pd_interfaces.srv import ComputeTrajectory, ResetEpisode
from pd_ros_common.names import CHILD_FRAME_ID, FRAME_ID


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
    episode: int, step: int, time_s: float, state: np.ndarray, status: int, lander_id: str = ""
) -> LanderState:
    msg = LanderState(
        episode=episode, step=step, mass=float(state[6]), status=int(status), lander_id=lander_id
    )
    msg.header.stamp = sim_time(time_s)
    msg.header.frame_id = FRAME_ID
    msg.position = vec3(state[0:3])
    msg.velocity = vec3(state[3:6])
    return msg


def state_from_msg(msg: Any) -> np.ndarray:
    """The physical 7-vector of a LanderState (or anything with position, velocity, mass)."""
    return state_vector(msg.position, msg.velocity, msg.mass)


def command_msg(state: LanderState, action: int, thrust_n: np.ndarray) -> ThrustCommand:
    """The command answering `state` (same episode, step, stamp, frame and lander_id)."""
    cmd = ThrustCommand(
        episode=state.episode, step=state.step, action=int(action), lander_id=state.lander_id
    )
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
        lander_id=state.lander_id,
    )
    msg.header.stamp = state.header.stamp
    msg.header.frame_id = state.header.frame_id
    return msg


def command_from_msg(msg: ThrustCommand, source: str = "") -> Command:
    """`source`: the publishing node's name, when the receiver resolved it."""
    t = from_vec3(msg.thrust)
    thrust = tuple(float(v) for v in t)
    return Command(int(msg.episode), int(msg.step), int(msg.action), thrust, source, msg.lander_id)


def result_msg(result: dict[str, Any]) -> EpisodeResult:
    """EpisodeResult of a `pd_core.sim.Simulator` result dict (stamp = time of flight)."""
    msg = EpisodeResult()
    msg.header.stamp = sim_time(result["time_of_flight"])
    msg.header.frame_id = FRAME_ID
    for key in ("episode", "steps", "rejected_commands", "missed_commands", "status"):
        setattr(msg, key, int(result[key]))
    msg.foreign_commands = int(result.get("foreign_commands", 0))
    msg.lander_id = str(result.get("lander_id", ""))
    for key in ("time_of_flight", "final_mass", "fuel"):
        setattr(msg, key, float(result[key]))
    for key in ("initial_position", "initial_velocity", "final_position", "final_velocity"):
        setattr(msg, key, vec3(result[key]))
    msg.landed = bool(result["landed"])
    msg.reason = str(result["reason"])
    return msg


def final_state(result: EpisodeResult) -> np.ndarray:
    return state_vector(result.final_position, result.final_velocity, result.final_mass)


# ---------------------------------------------------------------------------------- viewers
def ros_time(t_ns: int) -> Time:
    """A time in integer nanoseconds (the simulation clock, or the node's clock) as a stamp."""
    t_ns = int(t_ns)
    return Time(sec=t_ns // 1_000_000_000, nanosec=t_ns % 1_000_000_000)


def odometry_msg(
    state: np.ndarray, stamp: Time, nav_sigma: Sequence[float] = (0.0, 0.0)
) -> Odometry:
    """nav_msgs/Odometry of the lander: position and velocity in FRAME_ID (the child frame's
    axes are the landing site's: the 3-DOF lander has no attitude, so orientation is identity);
    covariances the navigation noise's variance (0 = exact), orientation and rates unknown."""
    msg = Odometry(child_frame_id=CHILD_FRAME_ID)
    msg.header.stamp = stamp
    msg.header.frame_id = FRAME_ID
    msg.pose.pose = _pose(state[0:3])
    msg.twist.twist.linear = vec3(state[3:6])
    pos_var, vel_var = float(nav_sigma[0]) ** 2, float(nav_sigma[1]) ** 2
    pose_cov = np.zeros((6, 6))
    twist_cov = np.zeros((6, 6))
    pose_cov[range(3), range(3)] = pos_var
    twist_cov[range(3), range(3)] = vel_var
    pose_cov[range(3, 6), range(3, 6)] = -1.0  # unknown (no attitude)
    twist_cov[range(3, 6), range(3, 6)] = -1.0
    msg.pose.covariance = pose_cov.reshape(-1).tolist()
    msg.twist.covariance = twist_cov.reshape(-1).tolist()
    return msg


def _pose(position: Sequence[float] | np.ndarray) -> Pose:
    p = Pose(orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0))
    p.position = Point(x=float(position[0]), y=float(position[1]), z=float(position[2]))
    return p


def pose_stamped(position: Sequence[float] | np.ndarray, stamp: Time) -> PoseStamped:
    msg = PoseStamped(pose=_pose(position))
    msg.header.stamp = stamp
    msg.header.frame_id = FRAME_ID
    return msg


def path_msg(poses: Sequence[PoseStamped], stamp: Time) -> Path:
    """nav_msgs/Path in FRAME_ID of `poses` (PoseStamped, e.g. from `pose_stamped`)."""
    msg = Path(poses=list(poses))
    msg.header.stamp = stamp
    msg.header.frame_id = FRAME_ID
    return msg


def plan_path_msg(response: ComputeTrajectory.Response, start_ns: int) -> Path:
    """nav_msgs/Path of an OCP answer's states, pose k stamped `start_ns + state_times[k]`."""
    times_ns = np.round(np.asarray(response.state_times, dtype=float) * 1e9).astype(np.int64)
    positions = from_vec3_list(response.positions)
    poses = [
        pose_stamped(p, ros_time(start_ns + int(t)))
        for p, t in zip(positions, times_ns, strict=True)
    ]
    return path_msg(poses, ros_time(start_ns))


def clock_msg(t_ns: int) -> Clock:
    """rosgraph_msgs/Clock at `t_ns` nanoseconds."""
    return Clock(clock=ros_time(t_ns))


# ---------------------------------------------------------------------------------- services
def reset_request(
    state: np.ndarray | None = None, seed: int = -1, lander_id: str = ""
) -> ResetEpisode.Request:
    """/sim/reset request: from `state` (7,), or Table 3 sampled (None); seed -1 = RNG goes on;
    `lander_id` "" = whichever simulator serves the name (refused when it is ambiguous)."""
    req = ResetEpisode.Request(
        use_initial_state=state is not None, seed=int(seed), lander_id=lander_id
    )
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
