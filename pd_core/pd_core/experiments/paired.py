"""Paired comparison of two agents flown on the same episodes (episode i on seed s + i): the
episodes only one of them lands, and the two-sided exact sign test on those pairs.

A campaign cell (`campaign.json`'s results[scenario][agent]) holds every failed episode's index
(`failed_episodes.episodes`) and details the first `campaign.LISTED_FAILURES_JSON`
(`failed_episodes.listed`); a file written before the full index pairs from the listed ones,
complete only where every failure is listed.

Two training runs' selection curves (`evals.csv`: success rate against gradient updates, each
network on the same selection episodes) pair by update count: `paired_curves`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, NamedTuple

from scipy.stats import binomtest


class Pairs(NamedTuple):
    """Episodes A lands and B does not (`a_only`), the reverse (`b_only`), and whether both
    cells listed every failure (else the counts are lower bounds)."""

    a_only: int
    b_only: int
    complete: bool


def sign_test(a_only: int, b_only: int) -> float:
    """Two-sided exact sign test p of `a_only` against `b_only` discordant pairs (1 with none)."""
    n = a_only + b_only
    return 1.0 if n == 0 else float(binomtest(min(a_only, b_only), n, 0.5).pvalue)


def pairs(cell_a: Mapping[str, Any], cell_b: Mapping[str, Any]) -> Pairs:
    """The discordant pairs of two campaign cells of the same scenario and episodes."""
    none = {"count": 0, "listed": []}
    fa, fb = cell_a.get("failed_episodes", none), cell_b.get("failed_episodes", none)
    ea, eb = _failed(fa), _failed(fb)
    complete = fa["count"] == len(ea) and fb["count"] == len(eb)
    return Pairs(len(eb - ea), len(ea - eb), complete)


def _failed(cell_failures: Mapping[str, Any]) -> set[int]:
    """The failed episode indices a cell holds: all of them, or the listed ones (older files)."""
    if "episodes" in cell_failures:
        return {int(i) for i in cell_failures["episodes"]}
    return {int(e["episode"]) for e in cell_failures["listed"]}


class CurvePairs(NamedTuple):
    """Networks at the same update count in two runs: how many, where A's success is higher,
    where lower, and the mean success of each over those networks."""

    networks: int
    a_higher: int
    a_lower: int
    mean_a: float
    mean_b: float


def paired_curves(curve_a: Mapping[int, float], curve_b: Mapping[int, float]) -> CurvePairs:
    """Pair two selection curves (updates -> success rate) on their common update counts."""
    common = sorted(set(curve_a) & set(curve_b))
    if not common:
        raise ValueError("the two curves share no update count")
    sa = [curve_a[u] for u in common]
    sb = [curve_b[u] for u in common]
    return CurvePairs(
        networks=len(common),
        a_higher=sum(x > y for x, y in zip(sa, sb, strict=True)),
        a_lower=sum(x < y for x, y in zip(sa, sb, strict=True)),
        mean_a=sum(sa) / len(sa),
        mean_b=sum(sb) / len(sb),
    )
