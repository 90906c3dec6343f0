"""`--help` of the nodes lists every parameter without starting ROS."""

from pd_ros_common.node_help import node_help, wants_help


def test_help_flag_only_before_ros_args():
    assert wants_help(["--help"])
    assert wants_help(["-h", "--ros-args", "-p", "x:=1"])
    assert not wants_help(["--ros-args", "-p", "help:=1", "--help"])
    assert not wants_help([])


def test_help_text_lists_parameters_with_defaults():
    text = node_help(
        "pd_sim_node",
        "pd_sim_node",
        "Simulates the lander.\n\nMore detail.",
        {"rate_hz": (5.0, "steps per second"), "lockstep": (False, "wait for commands", True)},
    )
    assert text.splitlines()[0].startswith("usage: pd_sim_node")
    assert "ros2 run pd_sim_node pd_sim_node" in text
    assert "Simulates the lander." in text and "More detail." not in text
    assert "rate_hz (float, default 5.0)" in text
    assert "lockstep (bool, default False)" in text
    assert "wait for commands" in text
