"""The powered-descent stack: pd_sim_node, pd_policy_node and pd_ocp_node, one process each.

    ros2 launch pd_bringup stack.launch.py
    ros2 launch pd_bringup stack.launch.py lockstep:=true seed:=7 model_path:=/path/to/model.pt
    ros2 launch pd_bringup stack.launch.py namespace:=/vehicle1 controller:=zemzev
    ros2 launch pd_bringup stack.launch.py managed:=true    # brought up by pd_lifecycle_manager

Parameters come from share/pd_bringup/config/{sim,policy,ocp}.yaml; the launch arguments below
override a few of them. Topic and service names are relative: with `namespace` (default: the
root), the whole stack lives under it (/vehicle1/lander/state, /vehicle1/sim/reset, ...), so two
stacks share a ROS domain without hearing each other. Needs a full ROS 2 install (`launch`,
`launch_ros`); on machines without them (pip wheels), `pd_demo` starts the same three processes
(see the README).

A node that exits on its own (a start-up error such as a missing model file or a bad parameter,
or a crash) ends the whole stack instead of leaving it running headless: the launch shuts down
with the reason `<node> exited with status N: <its last line on stderr>` (a node says a start-up
error in one line there). Exits while the launch is already shutting down (Ctrl-C) say nothing.

With `managed:=true` the three nodes start unconfigured (`autostart` false) and
pd_lifecycle_manager (in the same namespace) configures and activates them in order (OCP, policy,
simulator), watches them, and takes them down in reverse on Ctrl-C.
"""

from __future__ import annotations

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, EmitEvent, LogInfo, RegisterEventHandler
from launch.conditions import IfCondition
from launch.event_handlers import OnProcessExit, OnProcessIO
from launch.events import Shutdown
from launch.substitutions import LaunchConfiguration, PythonExpression
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue


def end_stack_on_exit(node: Node, name: str) -> list[RegisterEventHandler]:
    """Handlers that shut the launch down when `node` exits by itself, saying why: its exit
    status and the last line it wrote to stderr."""
    last_line = {"text": ""}

    def on_stderr(event) -> None:  # launch.events.process.ProcessIO
        lines = [ln.strip() for ln in event.text.decode(errors="replace").splitlines()]
        lines = [ln for ln in lines if ln]
        if lines:
            last_line["text"] = lines[-1]

    def on_exit(event, context) -> list | None:  # launch.events.process.ProcessExited
        if context.is_shutdown:
            return None  # stopped by the launch itself: nothing to report
        reason = f"{name} exited with status {event.returncode}"
        if last_line["text"]:
            reason += f": {last_line['text']}"
        return [
            LogInfo(msg=f"ending the stack: {reason}"),
            EmitEvent(event=Shutdown(reason=reason)),
        ]

    return [
        RegisterEventHandler(OnProcessIO(target_action=node, on_stderr=on_stderr)),
        RegisterEventHandler(OnProcessExit(target_action=node, on_exit=on_exit)),
    ]


def generate_launch_description() -> LaunchDescription:
    config = os.path.join(get_package_share_directory("pd_bringup"), "config")
    lockstep = LaunchConfiguration("lockstep")
    seed = LaunchConfiguration("seed")
    model_path = LaunchConfiguration("model_path")
    controller = LaunchConfiguration("controller")
    namespace = LaunchConfiguration("namespace")
    managed = LaunchConfiguration("managed")
    # each node's `autostart`: false when the manager brings the stack up
    autostart = {
        "autostart": ParameterValue(
            PythonExpression(["'", managed, "'.lower() not in ('true', '1')"]), value_type=bool
        )
    }
    arguments = [
        DeclareLaunchArgument(
            "managed",
            default_value="false",
            description="true: nodes wait unconfigured and pd_lifecycle_manager brings them up",
        ),
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
    ]
    nodes = {
        "pd_sim_node": Node(
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
                autostart,
            ],
        ),
        "pd_policy_node": Node(
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
                autostart,
            ],
        ),
        "pd_ocp_node": Node(
            package="pd_ocp_node",
            executable="pd_ocp_node",
            name="pd_ocp_node",
            namespace=namespace,
            output="screen",
            parameters=[os.path.join(config, "ocp.yaml"), autostart],
        ),
    }
    handlers = [h for name, node in nodes.items() for h in end_stack_on_exit(node, name)]
    manager = Node(
        package="pd_bringup",
        executable="pd_lifecycle_manager",
        name="pd_lifecycle_manager",
        namespace=namespace,
        output="screen",
        condition=IfCondition(managed),
    )
    return LaunchDescription([*arguments, *nodes.values(), manager, *handlers])
