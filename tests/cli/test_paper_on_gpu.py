"""scripts/paper_on_gpu.sh: its training step is the paper's Agent 1 (Table 2) at one gradient
update per env transition inside the budget, and a budget too small to train stops in one line."""

from __future__ import annotations

import json
import re
import shlex
import subprocess
from pathlib import Path

from pd_core.cli import train as pd_train
from pd_core.config import DQN_PAPER

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "paper_on_gpu.sh"


def script(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        ["bash", str(SCRIPT), *args], capture_output=True, text=True, timeout=120, check=False
    )


def test_the_training_step_is_table_2_at_one_update_per_transition(tmp_path, capsys):
    out = script("--dry-run", "--budget-s", "600", "--seed", "4", "--out", str(tmp_path))
    assert out.returncode == 0, out.stderr
    argv = shlex.split(out.stdout.strip())
    assert argv[0] == "pd-train"
    assert pd_train.main([*argv[1:], "--print-config"]) == 0
    cfg = json.loads(capsys.readouterr().out)
    assert cfg["preset"] == "paper-agent1" and cfg["seed"] == 4
    assert cfg["updates_per_step"] / cfg["num_envs"] == 1.0
    # n_T counts env steps; at one update per transition that is n_T updates
    assert cfg["target_period"] == DQN_PAPER.target_period_steps
    assert tuple(cfg["hidden"]) == DQN_PAPER.hidden and cfg["episodes"] == DQN_PAPER.episodes
    assert (cfg["batch_agent"], cfg["batch_demo"]) == (DQN_PAPER.batch_agent, DQN_PAPER.batch_demo)
    assert abs(cfg["max_minutes"] - (600 - 40) / 60) < 0.01
    assert cfg["run_dir"] == str(tmp_path / "run")


def test_agents_1_and_2_train_together_in_the_device_loop_by_default(tmp_path, capsys):
    out = script("--dry-run", "--out", str(tmp_path))
    argv = shlex.split(out.stdout.strip())
    assert pd_train.main([*argv[1:], "--print-config"]) == 0
    cfg = json.loads(capsys.readouterr().out)
    assert (cfg["loop"], cfg["agents"]) == ("device", "paper-agent2:1")
    alone = shlex.split(script("--dry-run", "--preset", "paper-agent2", "--agents", "").stdout)
    assert alone[alone.index("--preset") + 1] == "paper-agent2" and "--agents" not in alone


def test_a_budget_too_small_to_train_stops_in_one_line(tmp_path):
    out = script("--budget-s", "90", "--skip-checks", "--out", str(tmp_path))
    assert out.returncode == 1
    [line] = out.stderr.strip().splitlines()
    assert re.fullmatch(r"paper_on_gpu.sh: only (4\d|50) s left for training; stopping", line)
    assert not (tmp_path / "run").exists()


def test_an_unknown_flag_is_refused_with_the_usage():
    out = script("--budget", "5")
    assert out.returncode == 2
    assert out.stderr.splitlines()[0] == "paper_on_gpu.sh: unknown argument --budget"
