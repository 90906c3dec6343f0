"""pd_core.experiments.paired: discordant pairs of two campaign cells and the exact sign test."""

from __future__ import annotations

import pytest

from pd_core.experiments.paired import paired_curves, pairs, sign_test


def cell(failed: list[int], count: int | None = None) -> dict:
    listed = [{"episode": e, "seed": e} for e in failed]
    return {"episodes": 100, "failed_episodes": {"count": count or len(failed), "listed": listed}}


def test_sign_test_is_exact_two_sided_and_one_without_discordant_pairs():
    assert sign_test(0, 0) == 1.0
    assert sign_test(5, 5) == 1.0
    assert sign_test(10, 0) == pytest.approx(2 / 2**10)  # 2 P(X = 0), X ~ B(10, 1/2)
    assert sign_test(0, 10) == sign_test(10, 0)
    assert sign_test(9, 1) == pytest.approx(2 * 11 / 2**10)  # 2 P(X <= 1)
    assert sign_test(214, 103) < 1e-9  # the label-noise doc's pooled pairs


def test_pairs_count_episodes_only_one_agent_lands_and_flag_truncated_lists():
    a, b = cell([1, 2, 3]), cell([3, 4])
    assert pairs(a, b) == (1, 2, True)  # B fails 4 only: A lands it; A fails 1 and 2 only
    assert pairs(b, a) == (2, 1, True)
    assert pairs({"episodes": 100}, b) == (2, 0, True)  # no failure recorded: lands all
    assert not pairs(cell([1], count=250), b).complete


def test_paired_curves_compare_networks_at_common_update_counts_only():
    a = {2000: 0.95, 4000: 0.99, 6000: 0.97, 8000: 0.90}
    b = {2000: 0.90, 4000: 0.99, 6000: 0.98, 10000: 1.0}
    got = paired_curves(a, b)
    assert got.networks == 3  # 8000 and 10000 are in one curve only
    assert (got.a_higher, got.a_lower) == (1, 1)  # the tie at 4000 counts for neither
    assert got.mean_a == pytest.approx((0.95 + 0.99 + 0.97) / 3)
    assert got.mean_b == pytest.approx((0.90 + 0.99 + 0.98) / 3)
    with pytest.raises(ValueError, match="no update count"):
        paired_curves({2000: 1.0}, {4000: 1.0})


def test_cells_with_every_failed_index_pair_completely_past_the_listed_ones():
    """A cell lists 2 failures in detail but holds all 250 by index: the pairs are complete and
    count the unlisted ones too."""
    a = cell([0, 1], count=250)
    a["failed_episodes"]["episodes"] = list(range(250))
    b = cell([0, 1, 300])
    assert pairs(a, b) == (1, 248, True)  # A lands 300 only; B lands 2..249
    assert pairs(b, a) == (248, 1, True)
