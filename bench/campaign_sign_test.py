"""Paired sign test per scenario of a campaign (issue 32): episodes one agent lands and the
other does not, from `pd-eval ... --dispersions NAME --compare ... --out DIR`'s campaign.json.

    python bench/campaign_sign_test.py DIR/campaign.json [DIR2/campaign.json ...] [--agents A B]

Both agents fly the same episodes (episode i on seed s + i), so an episode is a pair. For each
scenario: b = episodes A lands and B does not, c = the reverse, and the two-sided exact sign
test p = min(1, 2 P(X <= min(b, c))), X ~ Binomial(b + c, 1/2) (`pd_core.experiments.paired`).
A cell lists at most 200 failed episodes (`LISTED_FAILURES_JSON`): where a count is larger the
pairs are incomplete, and the line says so. Several files (other campaigns, other seeds'
picks under the same labels) name their scenarios `file:scenario`. The last line pools every
scenario's pairs.
"""

from __future__ import annotations

import argparse
import json

from pd_core.experiments.paired import pairs, sign_test


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("campaign_json", nargs="+")
    ap.add_argument("--agents", nargs=2, default=None, help="two agent labels (default: first two)")
    a = ap.parse_args(argv)
    results = {}
    for path in a.campaign_json:
        with open(path) as f:
            cells = json.load(f)["results"]
        for scen, cell in cells.items():
            results[f"{path}:{scen}" if len(a.campaign_json) > 1 else scen] = cell
    first = next(iter(results.values()))
    names = a.agents or list(first)[:2]
    print(f"A = {names[0]}, B = {names[1]}")
    width = max(22, 2 + max(map(len, results)))
    head = f"{'scenario':<{width}}{'episodes':>9}{'A fails':>8}{'B fails':>8}"
    print(head + f"{'A ok, B not':>12}{'B ok, A not':>12}{'p':>8}")
    pooled = [0, 0, 0, 0, 0]  # episodes, A fails, B fails, A only lands, B only lands
    for scen, cells in results.items():
        ca, cb = cells[names[0]], cells[names[1]]
        pr = pairs(ca, cb)
        fails = [c.get("failed_episodes", {"count": 0})["count"] for c in (ca, cb)]
        n_ep = int(ca.get("episodes", 0))
        note = "" if pr.complete else "  (failures truncated)"
        print(
            f"{scen:<{width}}{n_ep:>9}{fails[0]:>8}{fails[1]:>8}{pr.a_only:>12}{pr.b_only:>12}"
            f"{sign_test(pr.a_only, pr.b_only):>8.3f}{note}"
        )
        for i, v in enumerate((n_ep, *fails, pr.a_only, pr.b_only)):
            pooled[i] += v
    n, f_a, f_b, b, c = pooled
    print(f"{'pooled':<{width}}{n:>9}{f_a:>8}{f_b:>8}{b:>12}{c:>12}{sign_test(b, c):>8.2g}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
