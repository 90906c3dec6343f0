"""pd_ocp_node: ROS 2 service over `pd_core.ocp.solve` (see `pd_ocp_node.node`)."""
