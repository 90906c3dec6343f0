"""scripts/train_recipe.sh: its stages are valid pd-train configurations chained file to file,
finished stages are skipped (an interrupted recipe restarts where it was), and a bad flag is one
line."""

from __future__ import annotations

import json
import shlex
import subprocess
from pathlib import Path

import pytest

from pd_core.cli import train as pd_train

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "train_recipe.sh"


def recipe(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        ["bash", str(SCRIPT), *args], capture_output=True, text=True, timeout=60, check=False
    )


def stage_configs(capsys, *args: str) -> list[dict]:
    """The resolved pd-train config of each stage the dry run prints."""
    out = recipe("--dry-run", *args)
    assert out.returncode == 0, out.stderr
    configs = []
    for line in out.stdout.strip().splitlines():
        argv = shlex.split(line)
        assert argv[0] == "pd-train", line
        assert pd_train.main([*argv[1:], "--print-config"]) == 0
        configs.append(json.loads(capsys.readouterr().out))
    return configs


def test_the_default_recipe_is_the_optimal_control_teachers(tmp_path, capsys):
    out = str(tmp_path / "r")
    assert stage_configs(capsys, "--out", out) == stage_configs(
        capsys, "--teacher", "ocp", "--out", out
    )
    (s1, s2) = stage_configs(capsys)
    assert (s1["run_dir"], s2["run_dir"]) == ("runs/ocp__1/stage1", "runs/ocp__1/stage2")


def test_zemzev_recipe_stages_are_chained_pd_train_configs_inside_sixty_minutes(tmp_path, capsys):
    out = tmp_path / "r"
    s1, s2, s3 = stage_configs(
        capsys, "--teacher", "zemzev-vernier", "--seed", "7", "--out", str(out)
    )
    assert s1["preset"] == "best" and s1["init_policy"] in ("", None)
    for cfg in (s2, s3):
        assert cfg["preset"] == "robust" and cfg["controller"] == "zemzev-vernier"
        assert cfg["layer"] is True and cfg["dispersions"] == "broad"
        assert cfg["precision_bonus"] == pytest.approx(10.0)
        assert cfg["near_pad"] is True
    assert s1["near_pad"] is False  # stage 1 is the paper's network; stage 2 widens it
    assert s2["init_policy"] == f"{out}/stage1/best.pt"
    assert s3["init_policy"] == f"{out}/stage2/best.pt"
    assert [c["seed"] for c in (s1, s2, s3)] == [7, 7, 7]
    assert [c["run_dir"] for c in (s1, s2, s3)] == [f"{out}/stage{k}" for k in (1, 2, 3)]
    # the wall-time budgets (demonstrations included) stay inside the 60 min target
    assert sum(c["max_minutes"] for c in (s1, s2, s3)) <= 60.0


def test_ocp_recipe_learns_from_the_optimal_control_teacher_only_on_an_update_budget(
    tmp_path, capsys
):
    out = tmp_path / "r"
    stages = stage_configs(capsys, "--teacher", "ocp", "--out", str(out))
    assert [c["preset"] for c in stages] == ["ocp", "ocp-dagger"]
    for cfg in stages:
        assert cfg["controller"] == "mpc-fuel-reserve-state" and cfg["demos"] == ""
        assert cfg["layer"] is True
    # stage 1 learns the `standard` dispersions; the DAgger rounds fly and label `broad`
    assert [c["dispersions"] for c in stages] == ["standard", "broad"]
    assert stages[0]["init_policy"] in ("", None) and stages[0]["label_episodes"] == 0
    # stage 2: aggregated DAgger rounds from stage 1's best.pt, no other starting file
    assert stages[1]["init_policy"] == f"{out}/stage1/best.pt"
    assert stages[1]["dagger_rounds"] > 0 and stages[1]["label_episodes"] > 0
    # no wall-time budget or evaluation clock, so a seed's file does not depend on the machine's
    # speed or load: stage 1 stops on its update count, stage 2 when its rounds end
    assert [c["max_minutes"] for c in stages] == [0.0, 0.0]
    assert stages[0]["max_updates"] == 201_000 and stages[1]["max_updates"] == 0
    assert all(c["eval_every_updates"] > 0 for c in stages)


def test_every_stage_trains_on_the_torch_threads_asked_two_by_default(tmp_path, capsys):
    out = str(tmp_path / "r")
    for args, want in (((), 2), (("--threads", "1"), 1)):
        stages = stage_configs(capsys, "--teacher", "ocp", "--out", out, *args)
        assert [c["torch_threads"] for c in stages] == [want, want]


def test_ablation_arms_change_only_the_demonstrator_and_keep_the_budget(tmp_path, capsys):
    base = stage_configs(capsys, "--teacher", "ocp", "--out", str(tmp_path / "ocp"))
    zv = stage_configs(
        capsys, "--teacher", "ocp", "--demonstrator", "zemzev-vernier", "--out", str(tmp_path / "z")
    )
    clock = stage_configs(
        capsys, "--teacher", "ocp", "--demonstrator", "mpc-fuel-reserve", "--out", str(tmp_path)
    )
    # ZEM/ZEV-vernier or the teacher handing over on its plan's clock (the recipe until
    # 2026-12-02): the same two stages, it flies the demonstrations and labels
    assert [c["controller"] for c in zv] == ["zemzev-vernier", "zemzev-vernier"]
    assert [c["controller"] for c in clock] == ["mpc-fuel-reserve", "mpc-fuel-reserve"]
    ignore = {"controller", "run_dir", "init_policy"}
    for a, b, c in zip(base, zv, clock, strict=True):
        assert {k: v for k, v in a.items() if k not in ignore} == {
            k: v for k, v in b.items() if k not in ignore
        }
        assert {k: v for k, v in c.items() if k not in ignore} == {
            k: v for k, v in b.items() if k not in ignore
        }
    (paper,) = stage_configs(capsys, "--teacher", "ocp", "--demonstrator", "open-loop")
    (none,) = stage_configs(capsys, "--teacher", "ocp", "--demonstrator", "none")
    assert paper["run_dir"] == "runs/ablation_open-loop__1/stage1"
    # the paper's 33 open-loop trajectories, no closed-loop teacher anywhere
    assert paper["demos"] == "data/demos_7x7x3.npz" and paper["batch_demo"] > 0
    assert paper["controller"] == "" and paper["controller_demo_episodes"] == 0
    assert paper["pretrain_updates"] == base[0]["pretrain_updates"]
    # no demonstrations at all: no demonstration batch, no pre-training, no margin loss
    assert none["batch_demo"] == 0 and none["pretrain_updates"] == 0 and none["margin"] == 0
    assert none["demos"] == "" and none["controller"] == ""
    for cfg in (paper, none):
        assert cfg["preset"] == "ocp" and cfg["init_policy"] in ("", None)
        assert cfg["layer"] is True and cfg["dispersions"] == "standard"
        # one stage holds the two-stage recipe's gradient updates: stage 1's budget and the
        # pre-training updates of stage 2's rounds (the initial network's and dagger_rounds more)
        rounds = base[1]["dagger_rounds"] + 1
        assert cfg["max_updates"] == base[0]["max_updates"] + rounds * base[1]["pretrain_updates"]
        assert cfg["max_minutes"] == 0.0 and cfg["eval_every_updates"] == 10_000


def test_recipe_from_a_given_stage1_policy_has_two_stages(tmp_path, capsys):
    start = tmp_path / "start.pt"
    start.write_bytes(b"")
    (s2,) = stage_configs(capsys, "--stage1", str(start), "--out", str(tmp_path / "r"))
    assert s2["init_policy"] == str(start) and s2["preset"] == "ocp-dagger"
    zv = ("--teacher", "zemzev-vernier")
    s2, s3 = stage_configs(capsys, *zv, "--stage1", str(start), "--out", str(tmp_path / "z"))
    assert s2["init_policy"] == str(start)
    assert s3["init_policy"] == f"{tmp_path}/z/stage2/best.pt"


def test_adapt_teacher_changes_only_stage_3s_teacher(tmp_path, capsys):
    args = ("--adapt", "--stage2", "models/pd_dqn_ocp.pt", "--out", str(tmp_path / "r"))
    (base,) = stage_configs(capsys, *args)
    (hold,) = stage_configs(capsys, *args, "--adapt-teacher", "mpc-fuel-reserve-state-lf-hold")
    assert base["controller"] == "mpc-fuel-reserve-state-lf"
    assert hold == {**base, "controller": "mpc-fuel-reserve-state-lf-hold"}
    (named,) = stage_configs(capsys, *args[:3], "--adapt-teacher", "mpc-fuel-reserve-state-lf-hold")
    assert named["run_dir"] == "runs/adapt_mpc-fuel-reserve-state-lf-hold__1/stage3"


def test_paper_inputs_fine_tune_without_the_near_pad_inputs(tmp_path, capsys):
    configs = stage_configs(
        capsys, "--teacher", "zemzev-vernier", "--paper-inputs", "--out", str(tmp_path / "r")
    )
    assert [c["near_pad"] for c in configs] == [False, False, False]


def test_finished_stages_are_skipped(tmp_path):
    for k in (1, 2, 3):
        (tmp_path / f"stage{k}").mkdir()
        (tmp_path / f"stage{k}" / "final.pt").write_bytes(b"")
    out = recipe("--out", str(tmp_path))
    assert out.returncode == 0, out.stderr
    assert out.stdout.count("exists, skipped") == 2
    assert f"{tmp_path}/stage2/best.pt" in out.stdout.splitlines()[-1]
    out = recipe("--teacher", "zemzev-vernier", "--out", str(tmp_path))
    assert out.returncode == 0, out.stderr
    assert out.stdout.count("exists, skipped") == 3
    assert f"{tmp_path}/stage3/final.pt" in out.stdout.splitlines()[-1]


def test_an_interrupted_stage_is_resumed_from_its_checkpoint(tmp_path):
    (tmp_path / "stage1").mkdir()
    (tmp_path / "stage1" / "final.pt").write_bytes(b"")
    (tmp_path / "stage2").mkdir()
    (tmp_path / "stage2" / "checkpoint.pt").write_bytes(b"not a checkpoint")
    out = recipe("--out", str(tmp_path))
    # stage 1 is skipped, stage 2 goes to `pd-train --resume`, which refuses the broken file
    # in one line, and the recipe stops there
    assert out.returncode == 2
    assert "stage1/final.pt exists, skipped" in out.stdout
    assert f"pd-train --resume {tmp_path}/stage2" in out.stdout
    assert "recipe done" not in out.stdout
    assert "cannot resume" in out.stderr


@pytest.mark.parametrize(
    ("args", "named"),
    [
        (["--seed", "x"], "--seed must be a non-negative integer"),
        (["--bogus"], "unknown argument '--bogus'"),
        (["--stage1", "/nonexistent.pt"], "--stage1 file not found"),
        (["--teacher", "zemzev"], "--teacher must be zemzev-vernier or ocp"),
        (["--teacher", "ocp", "--demonstrator", "x"], "--demonstrator must be mpc-fuel"),
        (["--teacher", "zemzev-vernier", "--demonstrator", "none"], "needs --teacher ocp"),
        (["--threads", "0"], "--threads must be a positive integer"),
        (["--adapt-teacher", "mpc-fuel-reserve-state-lf-hold"], "--adapt-teacher needs --adapt"),
        (["--adapt", "--adapt-teacher", "zemzev"], "--adapt-teacher must be mpc-fuel"),
    ],
)
def test_bad_flag_is_one_line(args, named):
    out = recipe(*args)
    assert out.returncode == 2
    err = out.stderr.strip().splitlines()
    assert len(err) == 1 and named in err[0], err
