"""pd_policy_node: ROS 2 adapter over `pd_core.load_policy` (see `pd_policy_node.node`)."""
