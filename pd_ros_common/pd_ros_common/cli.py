"""Command lines of the tools (pd_record, pd_replay, pd_demo): their own arguments apart from ROS's.

`ros2 run pd_bringup pd_record -o BAG --ros-args -r __ns:=/vehicle1` hands the tool its own
arguments and a `--ros-args ... [--]` section (any number of them, anywhere). argparse must never
see a ROS section: it would take `__ns:=/vehicle1` for a positional argument and leave rcl a bare
`-r`. `split_ros_args` takes every section out (checked with rclpy's own parser,
`rclpy.utilities.remove_ros_args`) and gives them to `rclpy.init` as one section.
Only `--ros-args` sections count: a bare `FROM:=TO` outside them (rcl's deprecated remap form)
is the tool's own, e.g. `pd_replay --remap FROM:=TO`, and never reaches rcl. A malformed ROS
section is a `UsageError` of one line (exit status 2).
"""

from __future__ import annotations

from collections.abc import Sequence

from rclpy.utilities import remove_ros_args


class UsageError(ValueError):
    """A command line that cannot be parsed (one line)."""


def split_ros_args(prog: str, argv: Sequence[str]) -> tuple[list[str], list[str]]:
    """(the tool's own arguments, ROS arguments for `rclpy.init(args=[prog, *ros])`) of `argv`
    (without the program name). The ROS arguments are `[]` or `["--ros-args", ...]`."""
    own: list[str] = []
    ros: list[str] = []
    in_section = seen = False
    for arg in argv:
        if arg == "--ros-args":
            in_section = seen = True
        elif in_section and arg == "--":
            in_section = False  # the explicit end of a section
        elif in_section:
            ros.append(arg)
        else:
            own.append(arg)
    ros = ["--ros-args", *ros] if seen else []
    try:
        left = remove_ros_args([prog, *ros])[1:]
    except RuntimeError as exc:  # rclpy's RCLInvalidROSArgsError, UnknownROSArgsError
        why = str(exc).split(", at ")[0]
        if type(exc).__name__ == "UnknownROSArgsError":
            why = f"unknown ROS argument(s) {why}"
        raise UsageError(f"{prog}: bad --ros-args: {why}") from None
    if left:
        raise UsageError(f"{prog}: bad --ros-args: not ROS arguments: {' '.join(left)}")
    return own, ros
