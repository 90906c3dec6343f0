"""Start-up parameters of the nodes: checked with the run-time check, one line when wrong,
integers accepted for doubles (issue 9 items 10 and 11), an unknown controller or runtime setting
refused, a good runtime setting flown."""

from __future__ import annotations

import pytest
from helpers import ProcessSet, wait_for

pytestmark = [pytest.mark.integration, pytest.mark.timeout(180)]

START_S = 90.0  # node start-up deadline on a loaded 2-core machine (torch import)


def _run_until_exit(tmp_path, package: str, params: dict) -> tuple[int, str]:
    procs = ProcessSet(tmp_path)
    try:
        p = procs.node(package, params)
        assert wait_for(lambda: not p.alive, START_S), f"{package} did not stop:\n{p.log()}"
        return p.proc.returncode, p.log()
    finally:
        procs.stop_all()


@pytest.mark.parametrize(
    ("package", "params", "code", "says"),
    [  # one of each kind per node (each case starts a process); the rest: test_ros_common.py
        ("pd_ocp_node", {"method": "bogus"}, 2, "parameter method: must be one of"),
        ("pd_ocp_node", {"control_points": -5}, 2, "parameter control_points: must be >= 2"),
        ("pd_sim_node", {"rate_hz": "abc"}, 2, "parameter rate_hz: expected a double"),
        ("pd_policy_node", {"stats_period_s": -1}, 2, "parameter stats_period_s: must be >= 0"),
        ("pd_policy_node", {"controller": "nope"}, 1, "controller 'nope': unknown controller"),
        ("pd_policy_node", {"layer": "maybe"}, 2, "parameter layer: must be one of file, always"),
        ("pd_policy_node", {"layer_settings": "gain=1"}, 1, "'gain' is unknown"),
        (  # a deprecated name beside its new one, disagreeing: refused, not guessed
            "pd_policy_node",
            {"shield": "never", "layer": "always"},
            2,
            "parameters shield (deprecated) and layer disagree: 'never' and 'always'",
        ),
    ],
)
def test_bad_start_up_parameter_is_one_line(tmp_path, package, params, code, says):
    rc, log = _run_until_exit(tmp_path, package, params)
    assert rc == code, log
    lines = log.strip().splitlines()
    assert len(lines) == 1 and says in lines[0] and package in lines[0], log
    assert "Traceback" not in log


def test_integers_accepted_for_doubles(tmp_path):
    procs = ProcessSet(tmp_path)
    try:
        sim = procs.node("pd_sim_node", {"rate_hz": 10, "max_time_s": 100, "start_episode": False})
        ocp = procs.node("pd_ocp_node", {"timeout_s": 30})
        pol = procs.node("pd_policy_node", {"stats_period_s": 5, "controller": "zemzev"})
        assert sim.wait_log("real time at 10 Hz", START_S), sim.log()
        assert ocp.wait_log("timeout_s=30.0", START_S), ocp.log()
        assert pol.wait_log("policy ready", START_S), pol.log()
        for p in (sim, ocp, pol):
            assert p.stop() == 0, p.log()
            assert "Traceback" not in p.log() and "context is invalid" not in p.log(), p.log()
    finally:
        procs.stop_all()


@pytest.mark.parametrize("name", ["layer_settings", "shield_settings"])
def test_runtime_settings_change_the_layer_the_policy_flies(tmp_path, name):
    """layer_settings 'nav_filter=0,touchdown_speed_mps=0': the node says which layer it flies;
    so does shield_settings, the deprecated old name, with one warning naming the new one."""
    procs = ProcessSet(tmp_path)
    try:
        pol = procs.node("pd_policy_node", {name: "nav_filter=0,touchdown_speed_mps=0"})
        assert pol.wait_log("policy ready", START_S), pol.log()
        assert "runtime settings nav_filter=0,touchdown_speed_mps=0" in pol.log(), pol.log()
        warned = [line for line in pol.log().splitlines() if "deprecated" in line]
        assert len(warned) == (name == "shield_settings"), pol.log()
        assert all(
            "parameter shield_settings is deprecated, use layer_settings" in w for w in warned
        )
        assert pol.stop() == 0, pol.log()
    finally:
        procs.stop_all()


def test_integers_for_doubles_are_stored_as_doubles(tmp_path, make_node, spin_until, service_ready):
    """`-p rate_hz:=10` reads back from the parameter server as the double 10.0 (issue 33; it
    kept the integer type), an integer parameter stays an integer."""
    from rcl_interfaces.msg import ParameterType
    from rcl_interfaces.srv import GetParameters

    procs = ProcessSet(tmp_path)
    try:
        sim = procs.node(
            "pd_sim_node", {"rate_hz": 10, "max_time_s": 100, "seed": 4, "start_episode": False}
        )
        assert sim.wait_log("real time at 10 Hz", START_S), sim.log()
        get = make_node("param_probe").create_client(GetParameters, "/pd_sim_node/get_parameters")
        assert service_ready(get, 30.0)
        future = get.call_async(GetParameters.Request(names=["rate_hz", "max_time_s", "seed"]))
        assert spin_until(future.done, 30.0)
        rate, max_time, seed = future.result().values
        assert (rate.type, rate.double_value) == (ParameterType.PARAMETER_DOUBLE, 10.0)
        assert (max_time.type, max_time.double_value) == (ParameterType.PARAMETER_DOUBLE, 100.0)
        assert (seed.type, seed.integer_value) == (ParameterType.PARAMETER_INTEGER, 4)
        assert sim.stop() == 0, sim.log()
    finally:
        procs.stop_all()
