"""pd_bringup files agree with the nodes: every declared parameter is in the YAML with its
default, and nothing else (the deprecated old names left out); the launch file compiles (it is
not imported: no `launch` here), and run against stand-ins of the launch classes, it ends the
stack when a node exits by itself."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
import yaml

from pd_ocp_node.node import NODE_NAME as OCP
from pd_ocp_node.node import PARAMETERS as OCP_PARAMS
from pd_policy_node.node import NODE_NAME as POLICY
from pd_policy_node.node import PARAMETERS as POLICY_PARAMS
from pd_policy_node.node import RENAMED as POLICY_RENAMED
from pd_sim_node.node import NODE_NAME as SIM
from pd_sim_node.node import PARAMETERS as SIM_PARAMS

pytestmark = [pytest.mark.integration]

BRINGUP = Path(__file__).resolve().parents[2] / "pd_bringup"


@pytest.mark.parametrize(
    ("file", "node", "params", "deprecated"),
    [
        ("sim.yaml", SIM, SIM_PARAMS, {}),
        ("policy.yaml", POLICY, POLICY_PARAMS, POLICY_RENAMED),
        ("ocp.yaml", OCP, OCP_PARAMS, {}),
    ],
)
def test_yaml_holds_declared_defaults(file, node, params, deprecated):
    data = yaml.safe_load((BRINGUP / "config" / file).read_text())
    values = data[f"/**/{node}"]["ros__parameters"]
    assert set(values) == set(params) - set(deprecated)
    assert set(deprecated.values()) <= set(values)  # each old name's new one is there
    for name in values:
        assert values[name] == params[name][0], name
        assert type(values[name]) is type(params[name][0]), name  # 5.0 stays a double, 0 an integer


def test_launch_file_compiles():
    src = (BRINGUP / "launch" / "stack.launch.py").read_text()
    compile(src, "stack.launch.py", "exec")
    assert "generate_launch_description" in src


class _Entity:
    """Stand-in for a launch/launch_ros class: keeps its arguments."""

    def __init__(self, *args, **kwargs) -> None:
        self.args, self.kwargs = args, kwargs


def _stub_launch_modules(monkeypatch) -> None:
    """Just enough of `launch` and `launch_ros` (not installed here) to run the launch file."""
    import types

    classes = {
        "launch": ["LaunchDescription"],
        "launch.actions": ["DeclareLaunchArgument", "EmitEvent", "LogInfo", "RegisterEventHandler"],
        "launch.event_handlers": ["OnProcessExit", "OnProcessIO"],
        "launch.conditions": ["IfCondition"],
        "launch.events": ["Shutdown"],
        "launch.substitutions": ["LaunchConfiguration", "PythonExpression"],
        "launch_ros": [],
        "launch_ros.actions": ["Node"],
        "launch_ros.parameter_descriptions": ["ParameterValue"],
    }
    for module, names in classes.items():
        mod = types.ModuleType(module)
        for name in names:
            setattr(mod, name, type(name, (_Entity,), {}))
        monkeypatch.setitem(sys.modules, module, mod)


def test_launch_file_ends_the_stack_when_a_node_exits(monkeypatch):
    """A node that exits by itself (here the policy node's one-line start-up error) shuts the
    launch down with that line as the reason; an exit during the launch's own shutdown does not.
    Run against stand-ins of the launch classes (no `launch` here)."""
    import types

    _stub_launch_modules(monkeypatch)
    ns: dict = {}
    path = BRINGUP / "launch" / "stack.launch.py"
    exec(compile(path.read_text(), str(path), "exec"), ns)
    monkeypatch.setitem(ns, "get_package_share_directory", lambda pkg: f"/share/{pkg}")
    entities = ns["generate_launch_description"]().args[0]
    nodes = [e for e in entities if type(e).__name__ == "Node"]
    handlers = [e.args[0] for e in entities if type(e).__name__ == "RegisterEventHandler"]
    assert [n.kwargs["name"] for n in nodes] == [SIM, POLICY, OCP, "pd_lifecycle_manager"]
    manager = nodes[-1]
    assert type(manager.kwargs["condition"]).__name__ == "IfCondition"  # managed:=true only
    for node in nodes[:3]:  # each node's autostart follows `managed`
        assert any("autostart" in p for p in node.kwargs["parameters"] if isinstance(p, dict))
    on_io = {
        h.kwargs["target_action"].kwargs["name"]: h for h in handlers if "on_stderr" in h.kwargs
    }
    on_exit = {
        h.kwargs["target_action"].kwargs["name"]: h for h in handlers if "on_exit" in h.kwargs
    }
    assert set(on_io) == set(on_exit) == {SIM, POLICY, OCP}

    line = "pd_policy_node: cannot start: no policy file at /nowhere/model.pt"
    on_io[POLICY].kwargs["on_stderr"](types.SimpleNamespace(text=f"{line}\n".encode()))
    running, stopping = (types.SimpleNamespace(is_shutdown=s) for s in (False, True))
    exited = types.SimpleNamespace(returncode=1)
    actions = on_exit[POLICY].kwargs["on_exit"](exited, running)
    reason = f"pd_policy_node exited with status 1: {line}"
    assert [type(a).__name__ for a in actions] == ["LogInfo", "EmitEvent"]
    assert actions[1].kwargs["event"].kwargs["reason"] == reason
    assert reason in actions[0].kwargs["msg"]
    assert on_exit[POLICY].kwargs["on_exit"](exited, stopping) is None  # Ctrl-C: no report
    # another node's exit names that node, without the policy node's line
    sim_exit = on_exit[SIM].kwargs["on_exit"](types.SimpleNamespace(returncode=-9), running)
    assert sim_exit[1].kwargs["event"].kwargs["reason"] == "pd_sim_node exited with status -9"
