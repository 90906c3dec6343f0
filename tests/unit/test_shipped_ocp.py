"""The policy flown by default, models/pd_dqn_ocp (issue 32): the file names only optimal-control
demonstrations and labels, starts from no other file, and flies behind the default runtime
layer."""

import json
from pathlib import Path

from pd_core.dqn.config import PRESETS
from pd_core.experiments.evaluate import rollout
from pd_core.runtime.config import RuntimeConfig
from pd_core.runtime.policy_file import SHIPPED_POLICY, load_policy

MODEL = (Path(__file__).resolve().parents[2] / SHIPPED_POLICY).with_suffix("")
TEACHER = PRESETS["ocp"]["controller"]  # the recipe's teacher, mpc-fuel-reserve-state


def test_the_default_policy_is_the_optimal_control_student() -> None:
    assert MODEL.name == "pd_dqn_ocp"


def test_every_demonstration_and_label_of_the_lineage_came_from_the_ocp_teacher() -> None:
    meta = json.loads(MODEL.with_suffix(".json").read_text())
    lineage = meta["training"]["lineage"]
    assert lineage["sources"] == [TEACHER]  # over every stage (scripts/ship_model.py)
    stages = lineage["stages"]
    assert len(stages) == 2
    for stage in stages:
        demos = stage["demos"]
        assert "file" not in demos  # no open-loop file, no ZEM/ZEV episode
        assert {c["name"] for c in demos["controller"]} == {TEACHER}
        assert all(c["behind_layer"] for c in demos["controller"])
        for labels in [demos.get("labels", {}), *demos.get("dagger_rounds", [])]:
            assert labels.get("teacher", TEACHER) == TEACHER
    assert "labels" not in stages[0]["demos"] and "labels" in stages[1]["demos"]
    assert len(stages[1]["demos"]["dagger_rounds"]) >= 1  # aggregated rounds after the first
    assert "init-policy" not in stages[0]["command"]  # from scratch


def test_it_flies_behind_the_default_runtime_layer_and_lands() -> None:
    rt = load_policy(MODEL.with_suffix(".pt"))
    assert rt.config == RuntimeConfig()
    ro = rollout(rt, 20, 0)
    assert ro.landed.sum() >= 19
    assert rt.changed < 0.2 * ro.steps.sum()  # the layer decides a minority of the steps
