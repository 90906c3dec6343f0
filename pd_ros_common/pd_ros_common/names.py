"""Topic and service names of the stack: relative, so they resolve in the node's namespace.

In the root namespace they are /lander/state, /lander/thrust_cmd, /lander/episode, /sim/reset and
/ocp/compute_trajectory; `-r __ns:=/vehicle1` (or the launch file's `namespace`) puts a whole
stack under /vehicle1/... so two stacks share a domain without hearing each other.
"""

from __future__ import annotations

STATE_TOPIC = "lander/state"
COMMAND_TOPIC = "lander/thrust_cmd"
EPISODE_TOPIC = "lander/episode"
GUIDANCE_TOPIC = "lander/guidance_status"
RESET_SERVICE = "sim/reset"
OCP_SERVICE = "ocp/compute_trajectory"

LANDER_TOPICS = (STATE_TOPIC, COMMAND_TOPIC, EPISODE_TOPIC, GUIDANCE_TOPIC)
POLICY_NODE = "pd_policy_node"  # the stack's commanding node (the simulator's command_source)


def resolve(name: str, namespace: str = "/") -> str:
    """Absolute name of a relative `name` in `namespace` ('/' or '/vehicle1')."""
    if name.startswith("/"):
        return name
    return f"{namespace.rstrip('/')}/{name}"
