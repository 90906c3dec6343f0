"""What pd_sim_node publishes besides /diagnostics: lander/state (every state, with the lander id)
and lander/episode (each result), and for viewers lander/odom (nav_msgs/Odometry, frame
landing_site, child frame lander) with every state, lander/path (nav_msgs/Path of the episode so
far) when the node asks, and in lockstep /clock (rosgraph_msgs/Clock: the simulation clock,
`pd_core.sim_pacing.Pacing.clock_ns`). In lockstep the odometry and path are stamped on that
clock; in real time on the node's clock.

Mechanism: `Outputs` makes the node's lifecycle publishers (owned by the node: cleanup destroys
them; inactive, they publish nothing) and keeps the poses of the current episode, one per
(episode, step), so a state published again adds none; `path_changed` says whether poses were
added since the last lander/path. Not thread-safe: the node calls it under its lock.
"""

from __future__ import annotations

from typing import Any

from nav_msgs.msg import Odometry, Path
from rosgraph_msgs.msg import Clock

from pd_core.sim import Simulator
from pd_interfaces.msg import EpisodeResult, LanderState
from pd_ros_common import diagnostics, names, qos
from pd_ros_common.convert import (
    clock_msg,
    odometry_msg,
    path_msg,
    pose_stamped,
    result_msg,
    ros_time,
    state_msg,
)
from pd_ros_common.lifecycle import ManagedNode


class Outputs:
    """The publishers of `node` (lander `lander_id`) and the path of the current episode."""

    def __init__(
        self, node: ManagedNode, lander_id: str, lockstep: bool, nav_sigma: tuple[float, float]
    ) -> None:
        pub, own = node.create_lifecycle_publisher, node.own
        self._node = node
        self.lander_id = lander_id
        self.lockstep = lockstep
        self._nav_sigma = nav_sigma  # the odometry's covariance
        self.state_pub = own(pub(LanderState, names.STATE_TOPIC, qos.LOOP_PUB_QOS))
        self.episode_pub = own(pub(EpisodeResult, names.EPISODE_TOPIC, qos.EPISODE_QOS))
        self.odom_pub = own(pub(Odometry, names.ODOM_TOPIC, qos.LOOP_PUB_QOS))
        self.path_pub = own(pub(Path, names.PATH_TOPIC, qos.PATH_QOS))
        self.clock_pub = own(pub(Clock, names.CLOCK_TOPIC, qos.CLOCK_QOS)) if lockstep else None
        self._path: list[Any] = []  # PoseStamped of the episode so far
        self._path_key: tuple[int, int] = (0, -1)  # (episode, step) of the last pose
        self._path_sent = 0  # poses in the last lander/path published

    def new_episode(self) -> None:
        """An episode starts: its path starts empty."""
        self._path = []
        self._path_sent = 0

    def state(self, s: Simulator, clock_ns: int) -> None:
        """lander/state of the simulator's current step (as navigation reports it), then /clock
        (lockstep), lander/odom, and the step's pose on the path."""
        observed = s.observed_state
        self.state_pub.publish(
            state_msg(s.episode, s.step, s.time_s, observed, s.status, self.lander_id)
        )
        stamp = self._stamp(clock_ns)
        if self.clock_pub is not None:
            self.clock_pub.publish(clock_msg(clock_ns))
        self.odom_pub.publish(odometry_msg(observed, stamp, self._nav_sigma))
        if (s.episode, s.step) != self._path_key:  # not again for a resend
            self._path_key = (s.episode, s.step)
            self._path.append(pose_stamped(observed[0:3], stamp))

    def result(self, result: dict[str, Any]) -> None:
        """An episode ended: its whole lander/path, then lander/episode."""
        self.publish_path()
        self.episode_pub.publish(result_msg(result))

    @property
    def path_changed(self) -> bool:
        """Poses were added since the last lander/path."""
        return len(self._path) != self._path_sent

    def publish_path(self) -> None:
        """lander/path of the episode so far (none before its first pose)."""
        if self._path:
            self.path_pub.publish(path_msg(self._path, self._path[-1].header.stamp))
            self._path_sent = len(self._path)

    def readers(self) -> dict[str, int]:
        """The subscriptions each data writer has matched, for /diagnostics."""
        return diagnostics.readers(self.state_pub, self.episode_pub, self.odom_pub, self.path_pub)

    def _stamp(self, clock_ns: int) -> Any:
        """Stamp of the viewer messages: the simulation clock in lockstep, else the node's."""
        if self.lockstep:
            return ros_time(clock_ns)
        return self._node.get_clock().now().to_msg()
