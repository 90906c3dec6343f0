"""The policy flown by default, models/pd_dqn_adapt (issue 68): stage 3 of the optimal-control
recipe from models/pd_dqn_ocp (issue 32). Every demonstration and label of both files came from
the optimal-control teacher behind the layer; the file sees the thrust fraction its layer counts
on and pins the layer that counts on 80 % thrust until the engine is measured."""

import json
from pathlib import Path

from pd_core.dqn.config import PRESETS
from pd_core.episodes import rollout
from pd_core.runtime.config import RuntimeConfig
from pd_core.runtime.policy_file import SHIPPED_POLICY, load_policy

ROOT = Path(__file__).resolve().parents[3]
MODEL = (ROOT / SHIPPED_POLICY).with_suffix("")
STAGE2 = ROOT / "models" / "pd_dqn_ocp"
TEACHER = PRESETS["ocp"]["controller"]  # the recipe's teacher, mpc-fuel-reserve-state
ADAPT = PRESETS["ocp-adapt"]


def _lineage(model: Path) -> dict:
    return json.loads(model.with_suffix(".json").read_text())["training"]["lineage"]


def _teachers_of(stage: dict) -> set[str]:
    demos = stage["demos"]
    assert "file" not in demos  # no open-loop file, no ZEM/ZEV episode
    assert all(c["behind_layer"] for c in demos["controller"])
    names = {c["name"] for c in demos["controller"]}
    for labels in [demos.get("labels", {}), *demos.get("dagger_rounds", [])]:
        names |= {labels["teacher"]} if "teacher" in labels else set()
    return names


def test_the_default_policy_is_stage_3_of_the_optimal_control_recipe() -> None:
    assert MODEL.name == "pd_dqn_adapt"
    lineage = _lineage(MODEL)
    assert lineage["recipe"].startswith("scripts/train_recipe.sh --adapt --stage2")
    (stage3,) = lineage["stages"]
    assert "--preset ocp-adapt" in stage3["command"]
    assert "--init-policy models/pd_dqn_ocp.pt" in stage3["command"]
    assert lineage["sources"] == [ADAPT["controller"]] == ["mpc-fuel-reserve-state-lf"]
    assert _teachers_of(stage3) == {ADAPT["controller"]}
    assert len(stage3["demos"]["dagger_rounds"]) >= 1


def test_its_starting_file_learnt_from_the_ocp_teacher_alone_from_scratch() -> None:
    lineage = _lineage(STAGE2)
    assert lineage["sources"] == [TEACHER]
    stages = lineage["stages"]
    assert len(stages) == 2 and "init-policy" not in stages[0]["command"]
    assert all(_teachers_of(s) == {TEACHER} for s in stages)
    assert "labels" not in stages[0]["demos"] and "labels" in stages[1]["demos"]


def test_it_pins_80_percent_until_measured_and_sees_the_thrust_fraction() -> None:
    rt = load_policy(MODEL.with_suffix(".pt"))
    assert rt.config == RuntimeConfig().with_settings(ADAPT["layer_settings"])
    assert rt.config.latency.unmeasured_thrust == 0.8 and not rt.config.rules.brake_mass_loss
    assert rt.actor.takes_thrust_fraction
    ro = rollout(rt, 20, 0)
    assert ro.landed.sum() >= 19
    assert rt.changed < 0.2 * ro.steps.sum()  # the layer decides a minority of the steps


def test_the_hold_file_differs_from_the_default_only_by_its_stage_3_teacher() -> None:
    hold = ROOT / "models" / "pd_dqn_hold"
    lineage = _lineage(hold)
    assert "--adapt-teacher mpc-fuel-reserve-state-lf-hold --seed 1" in lineage["recipe"]
    (stage3,) = lineage["stages"]
    assert stage3["command"] == (
        "pd-train --preset ocp-adapt --seed 1 --controller mpc-fuel-reserve-state-lf-hold"
        " --init-policy models/pd_dqn_ocp.pt"
    )
    assert _teachers_of(stage3) == {"mpc-fuel-reserve-state-lf-hold"}
    meta = {m: json.loads(m.with_suffix(".json").read_text()) for m in (hold, MODEL)}
    assert meta[hold]["runtime"] == meta[MODEL]["runtime"]
    rt = load_policy(hold.with_suffix(".pt"))
    assert rt.actor.takes_thrust_fraction
    assert rollout(rt, 20, 0).landed.sum() >= 19
