"""Who decided each command: the runtime layer's per-source counts from a bag's
lander/guidance_status and from the policy node's statistics line, to check they agree."""

from __future__ import annotations

import re
from collections import Counter
from pathlib import Path

from pd_bringup.bag import deserialize_all
from pd_core.runtime.decision import SOURCES
from pd_ros_common import names

# "... layer changed 12 of 260 actions (brake 3, guard 9, handover 0); ..." (Runtime.describe)
_STATS = re.compile(
    r"layer changed (\d+) of (\d+) actions \(brake (\d+), guard (\d+), handover (\d+)\)"
)


def bag_counts(bag: str | Path, namespace: str = "/") -> dict[str, int]:
    """{source: commands} of the GuidanceStatus messages in a bag (all sources, zeros included)."""
    topic = names.resolve(names.GUIDANCE_TOPIC, namespace)
    msgs = deserialize_all(bag, [topic]).get(topic, [])
    counted = Counter(SOURCES[int(m.source)] for m in msgs)
    return {s: counted.get(s, 0) for s in SOURCES}


def node_counts(log: str) -> dict[str, int] | None:
    """{source: commands} of the last statistics line in a policy node's log; None if none."""
    found = _STATS.findall(log)
    if not found:
        return None
    _, steps, brake, guard, handover = (int(v) for v in found[-1])
    changed = brake + guard + handover
    return {"network": steps - changed, "brake": brake, "guard": guard, "handover": handover}
