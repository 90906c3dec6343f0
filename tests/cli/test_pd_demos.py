"""`pd-demos`: the demonstration memory of pd-train's flags, as a file with its provenance."""

from __future__ import annotations

import json

import numpy as np

from pd_core.cli.demos import main

SMALL = ["--preset", "best", "--seed", "3", "--demos", "", "--controller-demo-episodes", "3"]


def test_pd_demos_writes_the_memory_with_its_provenance(tmp_path, capsys):
    out = tmp_path / "d.npz"
    assert main([*SMALL, "--out", str(out), "--json"]) == 0
    record = json.loads(capsys.readouterr().out)
    assert record["fields"]["seed"] == 3 and record["fields"]["controller_demo_episodes"] == 3
    assert record["build"]["controller"][0]["episodes"] == 3
    with np.load(out) as z:
        assert len(z["actions"]) == record["transitions"] > 50
        assert z["obs"].shape == (record["transitions"], 7)


def test_pd_demos_refuses_a_config_without_demonstrations_in_one_line(tmp_path, capsys):
    code = main([*SMALL, "--controller-demo-episodes", "0", "--out", str(tmp_path / "x.npz")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "no demonstrations" in err
    assert not (tmp_path / "x.npz").exists()
