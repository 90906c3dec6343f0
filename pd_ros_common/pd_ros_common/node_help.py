"""`--help` for the ROS nodes: their parameters, defaults and descriptions, without starting ROS.

The nodes keep their parameters in a dict `name -> (default, description, ...)`; this module turns
it into the usage text, so `pd_sim_node --help` answers like every other command here.
"""

from __future__ import annotations

import textwrap
from collections.abc import Mapping, Sequence
from typing import Any


def wants_help(argv: Sequence[str]) -> bool:
    """True if -h/--help comes before any --ros-args section."""
    for arg in argv:
        if arg == "--ros-args":
            return False
        if arg in ("-h", "--help"):
            return True
    return False


def node_help(
    executable: str, package: str, doc: str, parameters: Mapping[str, Sequence[Any]]
) -> str:
    """Usage text: how to run the node, the first paragraph of its docstring, each parameter."""
    lines = [
        f"usage: {executable} [--ros-args -p NAME:=VALUE ... --params-file FILE ...]",
        f"       ros2 run {package} {executable} [--ros-args ...]",
        "",
        doc.strip().split("\n\n")[0],
        "",
        "parameters (defaults in pd_bringup/config/*.yaml):",
    ]
    for name, spec in parameters.items():
        default, text = spec[0], spec[1]
        lines.append(f"  {name} ({type(default).__name__}, default {default!r})")
        lines += textwrap.wrap(text, width=96, initial_indent="      ", subsequent_indent="      ")
    return "\n".join(lines)
