"""pd_bringup files agree with the nodes: every declared parameter is in the YAML with its
default, and nothing else; the launch file compiles (it is not imported: no `launch` here)."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from pd_ocp_node.node import NODE_NAME as OCP
from pd_ocp_node.node import PARAMETERS as OCP_PARAMS
from pd_policy_node.node import NODE_NAME as POLICY
from pd_policy_node.node import PARAMETERS as POLICY_PARAMS
from pd_sim_node.node import NODE_NAME as SIM
from pd_sim_node.node import PARAMETERS as SIM_PARAMS

pytestmark = [pytest.mark.integration]

BRINGUP = Path(__file__).resolve().parents[2] / "pd_bringup"


@pytest.mark.parametrize(
    ("file", "node", "params"),
    [
        ("sim.yaml", SIM, SIM_PARAMS),
        ("policy.yaml", POLICY, POLICY_PARAMS),
        ("ocp.yaml", OCP, OCP_PARAMS),
    ],
)
def test_yaml_holds_declared_defaults(file, node, params):
    data = yaml.safe_load((BRINGUP / "config" / file).read_text())
    values = data[f"/**/{node}"]["ros__parameters"]
    assert set(values) == set(params)
    for name, spec in params.items():
        assert values[name] == spec[0], name
        assert type(values[name]) is type(spec[0]), name  # 5.0 stays a double, 0 an integer


def test_launch_file_compiles():
    src = (BRINGUP / "launch" / "stack.launch.py").read_text()
    compile(src, "stack.launch.py", "exec")
    assert "generate_launch_description" in src
