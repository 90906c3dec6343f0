"""The powered-descent stack: pd_sim_node, pd_policy_node and pd_ocp_node, one process each.

    ros2 launch pd_bringup stack.launch.py
    ros2 launch pd_bringup stack.launch.py lockstep:=true seed:=7 model_path:=/path/to/model.pt
    ros2 launch pd_bringup stack.launch.py namespace:=/vehicle1 controller:=zemzev

Parameters come from share/pd_bringup/config/{sim,policy,ocp}.yaml; the launch arguments below
override a few of them. Topic and service names are relative: with `namespace` (default: the
root), the whole stack lives under it (/vehicle1/lander/state, /vehicle1/sim/reset, ...), so two
stacks share a ROS domain without hearing each other. Needs a full ROS 2 install (`launch`,
`launch_ros`); on machines without them (pip wheels), `pd_demo` starts the same three processes
(see the README).
"""

from __future__ import annotations

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue


def generate_launch_description() -> LaunchDescription:
    config = os.path.join(get_package_share_directory("pd_bringup"), "config")
    lockstep = LaunchConfiguration("lockstep")
    seed = LaunchConfiguration("seed")
    model_path = LaunchConfiguration("model_path")
    controller = LaunchConfiguration("controller")
    namespace = LaunchConfiguration("namespace")
    return LaunchDescription(
        [
            DeclareLaunchArgument(
                "namespace", default_value="", description="namespace of the whole stack"
            ),
            DeclareLaunchArgument(
                "controller",
                default_value="dqn",
                description="pd_policy_node controller: dqn, zemzev, mpc-fuel, mpc-energy",
            ),
            DeclareLaunchArgument(
                "lockstep", default_value="false", description="pd_sim_node lockstep mode"
            ),
            DeclareLaunchArgument(
                "seed", default_value="0", description="seed of the simulator's first episode"
            ),
            DeclareLaunchArgument(
                "model_path",
                default_value="",
                description="policy file for pd_policy_node ('' = the shipped model)",
            ),
            Node(
                package="pd_sim_node",
                executable="pd_sim_node",
                name="pd_sim_node",
                namespace=namespace,
                output="screen",
                parameters=[
                    os.path.join(config, "sim.yaml"),
                    {
                        "lockstep": ParameterValue(lockstep, value_type=bool),
                        "seed": ParameterValue(seed, value_type=int),
                    },
                ],
            ),
            Node(
                package="pd_policy_node",
                executable="pd_policy_node",
                name="pd_policy_node",
                namespace=namespace,
                output="screen",
                parameters=[
                    os.path.join(config, "policy.yaml"),
                    {
                        "model_path": ParameterValue(model_path, value_type=str),
                        "controller": ParameterValue(controller, value_type=str),
                    },
                ],
            ),
            Node(
                package="pd_ocp_node",
                executable="pd_ocp_node",
                name="pd_ocp_node",
                namespace=namespace,
                output="screen",
                parameters=[os.path.join(config, "ocp.yaml")],
            ),
        ]
    )
