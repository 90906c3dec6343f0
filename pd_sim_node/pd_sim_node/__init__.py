"""pd_sim_node: ROS 2 adapter over `pd_core.sim.Simulator` (see `pd_sim_node.node`)."""
