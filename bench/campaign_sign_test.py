"""Paired sign test per scenario of a campaign (issue 32): episodes one agent lands and the
other does not, from `pd-eval ... --dispersions NAME --compare ... --out DIR`'s campaign.json.

    python bench/campaign_sign_test.py DIR/campaign.json [--agents A B]

Both agents fly the same episodes (episode i on seed s + i), so an episode is a pair. For each
scenario: b = episodes A lands and B does not, c = the reverse, and the two-sided exact sign
test p = min(1, 2 P(X <= min(b, c))), X ~ Binomial(b + c, 1/2). A cell lists at most 200 failed
episodes (`LISTED_FAILURES_JSON`): where a count is larger the pairs are incomplete, and the
line says so.
"""

from __future__ import annotations

import argparse
import json
from math import comb


def sign_test(b: int, c: int) -> float:
    n = b + c
    if n == 0:
        return 1.0
    k = min(b, c)
    return min(1.0, 2.0 * sum(comb(n, i) for i in range(k + 1)) / 2.0**n)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("campaign_json")
    ap.add_argument("--agents", nargs=2, default=None, help="two agent labels (default: first two)")
    a = ap.parse_args(argv)
    t = json.load(open(a.campaign_json))
    results = t["results"]
    first = next(iter(results.values()))
    names = a.agents or list(first)[:2]
    print(f"A = {names[0]}, B = {names[1]}")
    head = f"{'scenario':<22}{'episodes':>9}{'A fails':>8}{'B fails':>8}"
    print(head + f"{'A ok, B not':>12}{'B ok, A not':>12}{'p':>8}")
    for scen, cells in results.items():
        fa, fb = (cells[n].get("failed_episodes", {"count": 0, "listed": []}) for n in names)
        ea = {e["episode"] for e in fa["listed"]}
        eb = {e["episode"] for e in fb["listed"]}
        b, c = len(eb - ea), len(ea - eb)  # A lands & B fails, B lands & A fails
        n_ep = cells[names[0]].get("episodes", "?")
        note = "" if fa["count"] == len(ea) and fb["count"] == len(eb) else "  (failures truncated)"
        print(
            f"{scen:<22}{n_ep!s:>9}{fa['count']:>8}{fb['count']:>8}{b:>12}{c:>12}"
            f"{sign_test(b, c):>8.3f}{note}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
