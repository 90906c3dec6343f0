"""pd_policy_node refuses to start on a missing or mismatched model, saying which file and why."""

from __future__ import annotations

import json

import pytest
from helpers import ProcessSet, make_model, wait_for

pytestmark = [pytest.mark.integration, pytest.mark.timeout(300)]


def _start(tmp_path, model_path: str):
    procs = ProcessSet(tmp_path)
    try:
        p = procs.node("pd_policy_node", {"model_path": model_path})
        assert wait_for(lambda: not p.alive, 120.0), "the node did not stop"  # loaded machine
        return p.proc.returncode, p.log()
    finally:
        procs.stop_all()


def test_missing_model_stops_the_node(tmp_path):
    missing = tmp_path / "nothing_here.pt"
    code, log = _start(tmp_path, str(missing))
    assert code == 1
    assert str(missing) in log and "no such file" in log


def test_mismatched_model_stops_the_node(tmp_path):
    pt = make_model(tmp_path / "model.pt")
    js = pt.with_suffix(".json")
    meta = json.loads(js.read_text())
    meta["dt_s"] = 0.1
    js.write_text(json.dumps(meta))
    code, log = _start(tmp_path, str(pt))
    assert code == 1
    assert str(js) in log and "dt_s" in log and "does not match" in log
