"""pd-ocp command line: JSON output and exit codes."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from pd_core.cli.ocp import main


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "pd_core.cli.ocp", *args], capture_output=True, text=True, timeout=60
    )


def test_solve_json_success() -> None:
    p = run(
        "solve",
        "--position",
        "750",
        "0",
        "2500",
        "--velocity",
        "-40",
        "0",
        "-80",
        "--mass",
        "2000",
        "--json",
    )
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    assert out["success"] and 40 < out["time_of_flight"] < 70 and 250 < out["fuel"] < 350
    for k in ("message", "final_position", "final_velocity", "solve_time", "cost", "method"):
        assert k in out


def test_bad_request_exits_2(capsys: pytest.CaptureFixture) -> None:
    rc = main(
        [
            "solve",
            "--position",
            "0",
            "0",
            "-1",
            "--velocity",
            "0",
            "0",
            "-80",
            "--mass",
            "2000",
            "--json",
        ]
    )
    assert rc == 2
    assert "altitude" in json.loads(capsys.readouterr().out)["message"]
    with pytest.raises(SystemExit) as e:
        main(["solve", "--position", "0", "0"])
    assert e.value.code == 2


def test_help() -> None:
    for args in (["--help"], ["solve", "--help"], ["demos", "--help"]):
        assert run(*args).returncode == 0


def test_paper_flag_runs_finite_difference_slsqp_to_the_same_optimum(capsys) -> None:
    state = ["--position", "750", "0", "2500", "--velocity", "-40", "0", "-80", "--mass", "2000"]
    assert main(["solve", *state, "--json", "--paper"]) == 0
    paper = json.loads(capsys.readouterr().out)
    assert main(["solve", *state, "--json"]) == 0
    fast = json.loads(capsys.readouterr().out)
    assert paper["method"] == "slsqp" and fast["method"] == "qp"
    assert paper["success"] and paper["iterations"] > fast["iterations"]
    assert paper["cost"] == pytest.approx(fast["cost"], rel=5e-3)
