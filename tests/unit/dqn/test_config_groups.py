"""TrainConfig's groups (issue 70): every field in exactly one, a read-only view per group, a
nested form that flattens back to config.json's, and `pd-train --help` group by group."""

from __future__ import annotations

from dataclasses import fields

import pytest

from pd_core.cli.train import build_parser
from pd_core.dqn.config import GROUP_TITLES, GROUPS, TrainConfig, group_of, preset


def test_every_field_is_in_exactly_one_group():
    members = [m for group in GROUPS.values() for m in group]
    assert sorted(members) == sorted(f.name for f in fields(TrainConfig))
    assert len(members) == len(set(members))
    assert set(GROUP_TITLES) == set(GROUPS)
    assert {"network", "replay", "schedule", "demonstrations", "evaluation"} <= set(GROUPS)


def test_a_group_view_reads_its_fields_only_and_changes_nothing():
    cfg = preset("ocp-dagger")
    replay = cfg.group("replay")
    assert (replay.batch_agent, replay.batch_demo, replay.num_envs) == (128, 128, 32)
    assert cfg.group("evaluation").eval_episodes == 2000
    with pytest.raises(AttributeError, match="not in the config group 'replay'"):
        _ = replay.lr
    with pytest.raises(AttributeError, match="read-only"):
        replay.batch_agent = 1
    with pytest.raises(ValueError, match="no config group"):
        cfg.group("optimiser")
    assert group_of("lr") == "update" and group_of("eval_seed") == "evaluation"


def test_the_nested_form_flattens_back_to_the_flat_config():
    cfg = preset("ocp-adapt", seed=3)
    nested = cfg.grouped()
    assert list(nested) == list(GROUPS)
    flat = {k: v for group in nested.values() for k, v in group.items()}
    assert flat == cfg.to_dict()
    assert TrainConfig.from_dict(flat) == cfg


def test_help_lists_the_flags_group_by_group():
    text = build_parser().format_help()
    where = [text.index(f"\n{title}:\n") for title in GROUP_TITLES.values()]
    assert where == sorted(where)
    assert where[3] < text.index("\n  --batch-agent") < where[4]  # replay, then schedule
    assert where[-1] < text.index("\n  --eval-seed")
