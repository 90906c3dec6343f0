"""scripts/ship_model.py: a recipe's lineage is written from its stages' own metadata."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "ship_model.py"
_spec = importlib.util.spec_from_file_location("ship_model", SCRIPT)
ship_model = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(ship_model)
ship = ship_model.ship


def fake_run(run: Path, preset: str, init: str, demos: dict, updates: int) -> Path:
    run.mkdir(parents=True)
    cfg = {"preset": preset, "seed": 7, "init_policy": init}
    meta = {"training": {"config": cfg, "demos": demos, "updates": updates}}
    for policy in ("best", "final"):
        (run / f"{policy}.pt").write_bytes(b"weights of " + policy.encode())
        (run / f"{policy}.json").write_text(json.dumps(meta))
    (run / "episodes.csv").write_text(
        "episode,landed,return,k_velocity_mps,fuel_kg,epsilon,extra\n1,1,-3.0,0.1,300,0.1,x\n"
    )
    return run


TEACHER = {"name": "mpc-fuel-reserve", "behind_layer": True}


def test_the_lineage_names_each_stage_its_command_and_every_source(tmp_path: Path) -> None:
    one = fake_run(tmp_path / "r" / "stage1", "ocp", "", {"controller": [TEACHER]}, 201)
    two = fake_run(
        tmp_path / "r" / "stage2",
        "ocp-dagger",
        f"{one}/best.pt",
        {
            "controller": [TEACHER],
            "labels": {"teacher": "mpc-fuel-reserve"},
            "dagger_rounds": [{"teacher": "zemzev-vernier"}],
            "file": {"path": "data/demos.npz", "transitions": 9},
        },
        54,
    )
    out = tmp_path / "models" / "x"
    ship(two, out, "best", "train_recipe.sh --seed 7", [one, two])
    assert out.with_suffix(".pt").read_bytes() == b"weights of best"
    lineage = json.loads(out.with_suffix(".json").read_text())["training"]["lineage"]
    assert lineage["recipe"] == "train_recipe.sh --seed 7"
    assert lineage["sources"] == ["file data/demos.npz", "mpc-fuel-reserve", "zemzev-vernier"]
    first, second = lineage["stages"]
    assert first["command"] == "pd-train --preset ocp --seed 7" and first["updates"] == 201
    assert second["command"] == f"pd-train --preset ocp-dagger --seed 7 --init-policy {one}/best.pt"
    assert second["policy"] == f"{two}/best.pt" and second["updates"] == 54


def test_a_run_without_episodes_ships_no_episode_log(tmp_path: Path) -> None:
    run = fake_run(tmp_path / "stage2", "ocp-dagger", "", {}, 1)
    (run / "episodes.csv").write_text("episode,landed,return,k_velocity_mps,fuel_kg,epsilon\n")
    written = ship(run, tmp_path / "m", "best")
    assert [p.suffix for p in written] == [".pt", ".json"]
    assert not (tmp_path / "m.episodes.csv").exists()


def test_stages_must_end_with_the_shipped_run(tmp_path: Path) -> None:
    one = fake_run(tmp_path / "stage1", "ocp", "", {}, 1)
    two = fake_run(tmp_path / "stage2", "ocp-dagger", "", {}, 1)
    with pytest.raises(ValueError, match="must end with the shipped run"):
        ship(two, tmp_path / "m", "best", "", [two, one])


def test_a_stage_taught_by_a_teacher_its_preset_does_not_name_says_so(tmp_path: Path) -> None:
    run = fake_run(tmp_path / "stage3", "ocp-adapt", "models/a.pt", {"controller": [TEACHER]}, 9)
    meta = json.loads((run / "final.json").read_text())

    def command(controller: str) -> str:
        meta["training"]["config"]["controller"] = controller
        (run / "final.json").write_text(json.dumps(meta))
        ship(run, tmp_path / "models" / "x", "final", "train_recipe.sh --adapt", [run])
        shipped = json.loads((tmp_path / "models" / "x.json").read_text())
        (stage,) = shipped["training"]["lineage"]["stages"]
        return stage["command"]

    assert command("mpc-fuel-reserve-state-lf-hold") == (
        "pd-train --preset ocp-adapt --seed 7 --controller mpc-fuel-reserve-state-lf-hold"
        " --init-policy models/a.pt"
    )
    assert "--controller" not in command("mpc-fuel-reserve-state-lf")  # the preset's own
