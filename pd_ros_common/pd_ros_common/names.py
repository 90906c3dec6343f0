"""Topic and service names of the stack: relative, so they resolve in the node's namespace.

In the root namespace they are /lander/state, /lander/thrust_cmd, /lander/episode, /sim/reset and
/ocp/compute_trajectory; `-r __ns:=/vehicle1` (or the launch file's `namespace`) puts a whole
stack under /vehicle1/... so two stacks share a domain without hearing each other.

What viewers read (rviz, Foxglove): lander/odom (nav_msgs/Odometry), lander/path and ocp/plan
(nav_msgs/Path), all in the frame `FRAME_ID`. `/clock` and `/diagnostics` are absolute, as ROS
tools expect them (one clock and one diagnostics topic per domain).
"""

from __future__ import annotations

STATE_TOPIC = "lander/state"
COMMAND_TOPIC = "lander/thrust_cmd"
EPISODE_TOPIC = "lander/episode"
GUIDANCE_TOPIC = "lander/guidance_status"
RESET_SERVICE = "sim/reset"
OCP_SERVICE = "ocp/compute_trajectory"
ODOM_TOPIC = "lander/odom"  # nav_msgs/Odometry of the lander, one per state (pd_sim_node)
PATH_TOPIC = "lander/path"  # nav_msgs/Path of the episode flown so far (pd_sim_node)
PLAN_TOPIC = "ocp/plan"  # nav_msgs/Path of the last successful OCP answer (pd_ocp_node)
CLOCK_TOPIC = "/clock"  # rosgraph_msgs/Clock, simulation time (pd_sim_node in lockstep)
DIAGNOSTICS_TOPIC = "/diagnostics"  # diagnostic_msgs/DiagnosticArray, 1 Hz from every node

FRAME_ID = "landing_site"  # x downrange, y crossrange, z altitude (m)
CHILD_FRAME_ID = "lander"  # the lander's body frame (axes parallel to the landing site's)

LANDER_TOPICS = (STATE_TOPIC, COMMAND_TOPIC, EPISODE_TOPIC, GUIDANCE_TOPIC)
VIEW_TOPICS = (ODOM_TOPIC, PATH_TOPIC, PLAN_TOPIC)
POLICY_NODE = "pd_policy_node"  # the stack's commanding node (the simulator's command_source)
SIM_NODE = "pd_sim_node"
OCP_NODE = "pd_ocp_node"
# The managed nodes in the order a lifecycle manager brings them up (down in reverse).
MANAGED_NODES = (OCP_NODE, POLICY_NODE, SIM_NODE)
# lifecycle_msgs/TransitionEvent of each managed node (rcl_lifecycle's <node>/transition_event)
TRANSITION_TOPICS = tuple(f"{n}/transition_event" for n in MANAGED_NODES)
RECORD_TOPICS = (*LANDER_TOPICS, *VIEW_TOPICS, DIAGNOSTICS_TOPIC, *TRANSITION_TOPICS)


def resolve(name: str, namespace: str = "/") -> str:
    """Absolute name of a relative `name` in `namespace` ('/' or '/vehicle1')."""
    if name.startswith("/"):
        return name
    return f"{namespace.rstrip('/')}/{name}"
