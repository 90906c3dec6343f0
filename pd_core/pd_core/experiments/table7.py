"""Table 7 of the paper as blocks side by side: the paper's agents, then every agent we evaluated.

A block is the median/min/max of the final-state quantities over the evaluation episodes, plus
success and soft-landing rates (which the paper gives only in words: Sec. 4.4).
"""

from __future__ import annotations

from typing import Any

from pd_core.config import PAPER_TABLE7
from pd_core.experiments.evaluate import LABELS, QUANTITIES

PAPER_BLOCKS = {"paper Agent 1": "agent1", "paper Agent 2": "agent2"}
"""paper agents printed first: Agent 1 trained with demonstrations, Agent 2 without (Sec. 3.2)"""


def _cell(t: tuple[float, float, float]) -> str:
    return f"{t[0]:.3g} [{t[1]:.3g}, {t[2]:.3g}]"


def table7_blocks(summaries: dict[str, dict[str, Any]]) -> str:
    """Rows: Table 7's quantities as `median [min, max]`, then success and soft-landing rates;
    columns: the paper's Agents 1 and 2, then each summary (of `evaluate.summarise`) by name."""
    cols: dict[str, dict[str, str]] = {}
    for label, key in PAPER_BLOCKS.items():
        cols[label] = {q: _cell(PAPER_TABLE7[key][q]) for q in QUANTITIES}
        cols[label].update(success="-", soft="-", episodes="1000")
    for name, s in summaries.items():
        t = s["table7"]
        cols[name] = {q: _cell((t[q]["median"], t[q]["min"], t[q]["max"])) for q in QUANTITIES}
        cols[name].update(
            success=f"{100 * s['success_rate']:.1f} %",
            soft=f"{100 * s['soft_landing_rate']:.1f} %",
            episodes=str(s["episodes"]),
        )
    rows = [(LABELS[q], q) for q in QUANTITIES] + [
        ("Success rate", "success"),
        ("Soft landing (vk > -2 m/s)", "soft"),
        ("Episodes", "episodes"),
    ]
    cells = [v for col in cols.values() for v in col.values()]
    width = 2 + max(24, *map(len, cells), *map(len, cols))
    head = f"{'Table 7 (median [min, max])':<28}" + "".join(f"{n:>{width}}" for n in cols)
    lines = [head, "-" * len(head)]
    for label, key in rows:
        lines.append(f"{label:<28}" + "".join(f"{c[key]:>{width}}" for c in cols.values()))
    return "\n".join(lines)
