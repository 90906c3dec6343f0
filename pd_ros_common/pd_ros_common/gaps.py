"""Messages that never arrived, from the publishers' sequence numbers.

A KEEP_LAST writer whose history is full drops its oldest sample for every reader, acknowledged or
not, and the reader is not told (no message-lost event). But every message carries its writer's
gid and sequence number (rclpy's MessageInfo, on a callback that takes two arguments), so a
reader sees the hole: `SequenceGaps.update(info)` returns how many messages of that writer were
skipped since the last one it saw (0 for a writer's first message: what was published before the
reader matched is not a loss).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any


class SequenceGaps:
    """Per-publisher sequence tracking; `total` messages missing so far."""

    def __init__(self) -> None:
        self._last: dict[bytes, int] = {}
        self.total = 0

    def update(self, info: Mapping[str, Any]) -> tuple[int, int, int]:
        """(missing, first missing seq, last missing seq) for this message's publisher."""
        seq = info.get("publication_sequence_number")
        gid = info.get("publisher_gid")
        if seq is None or not gid:
            return 0, 0, 0
        key = bytes(gid["data"])
        last = self._last.get(key)
        self._last[key] = seq if last is None else max(seq, last)
        if last is None or seq <= last + 1:
            return 0, 0, 0
        missing = seq - last - 1
        self.total += missing
        return missing, last + 1, seq - 1
