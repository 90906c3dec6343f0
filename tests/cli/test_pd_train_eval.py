"""pd-train and pd-eval end to end: a tiny run, its model evaluated, --json, refusals, --help."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from pd_core.cli import evaluate as pd_eval
from pd_core.cli import train as pd_train


def test_help_lists_documented_flags(capsys):
    with pytest.raises(SystemExit) as e:
        pd_train.main(["--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    for flag in ("--preset", "--batch-demo", "--double-dqn", "--n-step", "--margin", "--resume"):
        assert flag in out
    assert "k_demo" in out  # field docstrings become help texts
    with pytest.raises(SystemExit):
        pd_eval.main(["--help"])
    assert "--fuel-optimal" in capsys.readouterr().out


def test_print_config_resolves_preset_and_flags(capsys):
    assert pd_train.main(["--preset", "paper-agent2", "--gamma", "0.9", "--print-config"]) == 0
    cfg = json.loads(capsys.readouterr().out)
    assert cfg["batch_agent"] == 200 and cfg["batch_demo"] == 0 and cfg["gamma"] == 0.9


def test_train_then_eval_json_and_figures(tmp_path, capsys):
    run = tmp_path / "run"
    rc = pd_train.main(
        [
            "--preset",
            "best",
            "--seed",
            "4",
            "--hidden",
            "16,16",
            "--num-envs",
            "4",
            "--controller-demo-episodes",
            "3",
            "--pretrain-updates",
            "10",
            "--max-updates",
            "40",
            "--learning-starts",
            "100",
            "--batch-agent",
            "8",
            "--batch-demo",
            "8",
            "--eval-every-s",
            "1000",
            "--eval-episodes",
            "5",
            "--progress",
            "false",
            "--run-dir",
            str(run),
            "--json",
        ]
    )
    assert rc == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["updates"] == 40
    for f in (
        "final.pt",
        "final.json",
        "checkpoint.pt",
        "episodes.csv",
        "metrics.csv",
        "evals.csv",
        "config.json",
        "curves.png",
    ):
        assert (run / f).is_file(), f
    meta = json.loads((run / "final.json").read_text())
    assert meta["training"]["seed"] == 4 and meta["network"]["hidden"] == [16, 16]
    assert meta["training"]["config"]["preset"] == "best"

    rc = pd_eval.main(
        [
            str(run / "final.pt"),
            "--episodes",
            "6",
            "--seed",
            "1",
            "--json",
            "--figures",
            str(tmp_path / "figs"),
            "--compare",
            "ref=controller:zemzev",
            "--training-log",
            f"run={run / 'episodes.csv'}",
        ]
    )
    assert rc == 0
    res = json.loads(capsys.readouterr().out)
    assert res["episodes"] == 6 and res["seed"] == 1
    assert set(res["table7"]) == {
        "norm_ij_position_m",
        "norm_ij_velocity_mps",
        "k_velocity_mps",
        "fuel_kg",
    }
    for k in ("fig5", "fig6", "fig7", "fig8"):
        assert (tmp_path / "figs").joinpath(res["figures"][k].split("/")[-1]).is_file()

    # resume for a few more updates
    rc = pd_train.main(
        ["--resume", str(run), "--max-updates", "50", "--progress", "false", "--json"]
    )
    assert rc == 0
    assert json.loads(capsys.readouterr().out)["updates"] == 50


def test_eval_controller_text_report(capsys):
    assert pd_eval.main(["--controller", "zemzev", "--episodes", "20", "--seed", "2"]) == 0
    out = capsys.readouterr().out
    assert "Norm ij-position (m)" in out and "6.04" in out and "success rate" in out


def test_eval_of_a_policy_file_says_how_often_its_runtime_layer_changed_the_network(capsys):
    """The report counts the actions the layer changed, per rule, over every decision flown."""
    shipped = Path(__file__).resolve().parents[2] / "models" / "pd_dqn_robust.pt"
    argv = [
        str(shipped),
        "--episodes",
        "10",
        "--seed",
        "3",
        "--compare",
        "zz=layer:controller:zemzev",
    ]
    assert pd_eval.main(argv) == 0
    out = capsys.readouterr().out
    line = next(x for x in out.splitlines() if x.startswith("runtime layer: changed "))
    changed, steps = (int(v) for v in re.findall(r"changed (\d+) of (\d+) actions", line)[0])
    rules = [int(v) for v in re.findall(r"(?:brake|guard|handover) (\d+)", line)]
    assert 10 * 150 < steps < 10 * 400 and sum(rules) == changed and 0 < changed < steps
    assert line.endswith(f", {100 * changed / steps:.1f} %")
    assert "runtime layer of zz: changed " in out  # a compared agent behind the layer too


def test_eval_refuses_mismatched_model(tmp_path, capsys):
    import torch

    from pd_core.dqn.network import QNetwork
    from pd_core.runtime.config import RuntimeConfig
    from pd_core.runtime.policy_file import save_policy

    path = save_policy(tmp_path / "m", QNetwork(7, 147, (8,)), RuntimeConfig.off())
    js = path.with_suffix(".json")
    meta = json.loads(js.read_text())
    meta["state_scale"] = [1.0] * 7
    js.write_text(json.dumps(meta))
    assert pd_eval.main([str(path), "--episodes", "2"]) == 2
    assert "state_scale" in capsys.readouterr().err
    del torch
