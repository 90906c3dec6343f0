"""The minibatch plan of Sec. 2.3: which memory each row of an update's minibatch comes from.

One plan serves every training path: the numpy reference (`Trainer.sample`), the device update
(`pd_core.dqn.device.DeviceUpdate`) and the device-resident loop (`pd_core.dqn.device_loop`).
An update draws `batch_agent` rows from the agent's replay memory, then `batch_demo` rows from
the demonstration memory (none when there is no demonstration memory or `batch_demo` is 0);
pre-training draws all `batch_agent + batch_demo` rows from the demonstrations. Eq. 11's
large-margin loss applies to the demonstration rows, from `margin_from` on.
"""

from __future__ import annotations

from typing import NamedTuple

from pd_core.dqn.config import TrainConfig

REPLAY = "replay"
DEMO = "demo"


class MinibatchPlan(NamedTuple):
    """Rows of one update's minibatch, in order."""

    parts: tuple[tuple[str, int], ...]
    """(memory, rows): `REPLAY` or `DEMO`, drawn in this order (the index draws' order too)"""
    margin_from: int | None
    """first row of the large-margin loss (the demonstration rows); None: no such loss"""

    @property
    def rows(self) -> int:
        return sum(n for _, n in self.parts)

    def rows_of(self, memory: str) -> int:
        return sum(n for m, n in self.parts if m == memory)


def minibatch_plan(
    batch_agent: int, batch_demo: int, margin: float, *, has_demo: bool, pretraining: bool = False
) -> MinibatchPlan:
    """The plan of an update with these Table 2 sizes (`TrainConfig.batch_agent`, `batch_demo`,
    `margin`); `has_demo`: a demonstration memory exists. ValueError for pre-training without
    demonstrations."""
    if pretraining:
        if not has_demo:
            raise ValueError("pre-training needs a demonstration memory")
        parts: tuple[tuple[str, int], ...] = ((DEMO, batch_agent + batch_demo),)
        demo_from: int | None = 0
    elif has_demo and batch_demo > 0:
        parts, demo_from = ((REPLAY, batch_agent), (DEMO, batch_demo)), batch_agent
    else:
        parts, demo_from = ((REPLAY, batch_agent),), None
    return MinibatchPlan(parts, demo_from if margin > 0.0 else None)


def plan_of(cfg: TrainConfig, *, has_demo: bool, pretraining: bool = False) -> MinibatchPlan:
    """`minibatch_plan` of a training config's sizes and margin."""
    return minibatch_plan(
        cfg.batch_agent, cfg.batch_demo, cfg.margin, has_demo=has_demo, pretraining=pretraining
    )
