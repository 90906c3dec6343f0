"""The minibatch plan (Sec. 2.3, Table 2): agent rows, then demonstration rows under Eq. 11."""

import pytest

from pd_core.dqn.minibatch import DEMO, REPLAY, minibatch_plan


def test_an_update_draws_agent_rows_then_demonstration_rows_with_the_margin_on_the_latter():
    plan = minibatch_plan(32, 96, 0.8, has_demo=True)
    assert plan.parts == ((REPLAY, 32), (DEMO, 96))
    assert plan.margin_from == 32 and plan.rows == 128 and plan.rows_of(DEMO) == 96


def test_pretraining_draws_the_whole_minibatch_from_the_demonstrations():
    plan = minibatch_plan(32, 96, 0.8, has_demo=True, pretraining=True)
    assert plan.parts == ((DEMO, 128),) and plan.margin_from == 0
    with pytest.raises(ValueError, match="pre-training needs"):
        minibatch_plan(32, 96, 0.8, has_demo=False, pretraining=True)


@pytest.mark.parametrize(("batch_demo", "has_demo"), [(0, True), (96, False)])
def test_without_demonstration_rows_the_minibatch_is_the_agents_alone(batch_demo, has_demo):
    plan = minibatch_plan(128, batch_demo, 0.8, has_demo=has_demo)
    assert plan.parts == ((REPLAY, 128),) and plan.margin_from is None


def test_no_margin_means_no_large_margin_rows():
    assert minibatch_plan(32, 96, 0.0, has_demo=True).margin_from is None
