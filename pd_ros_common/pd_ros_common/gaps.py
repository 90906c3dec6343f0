"""Messages that never arrived, from the publishers' sequence numbers.

A KEEP_LAST writer whose history is full drops its oldest sample for every reader, acknowledged or
not, and the reader is not told (no message-lost event). But every message carries its writer's
gid and sequence number (rclpy's MessageInfo, on a callback that takes two arguments), so a
reader sees the hole: `SequenceGaps.update(info)` returns how many messages of that writer were
skipped since the last one it saw (0 for a writer's first message: what was published before the
reader matched is not a loss).

A reader that must have every message of a writer that appears after it started (a recorder
while a restarted simulator comes up) passes `is_new(gid) -> bool`: for such a writer's first
message, sequence number n, the n - 1 messages it published before the reader matched it are
counted in `before_match` (sequence numbers start at 1), and `update` says so through
`last_before_match`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any


class SequenceGaps:
    """Per-publisher sequence tracking; `total` messages missing so far, and with `is_new`,
    `before_match` messages new publishers sent before this reader matched them."""

    def __init__(self, is_new: Callable[[bytes], bool] | None = None) -> None:
        self._last: dict[bytes, int] = {}
        self.total = 0
        self.is_new = is_new
        self.before_match = 0
        self.last_before_match = 0  # of the last update: a new publisher's first message

    def update(self, info: Mapping[str, Any]) -> tuple[int, int, int]:
        """(missing, first missing seq, last missing seq) for this message's publisher."""
        seq = info.get("publication_sequence_number")
        gid = info.get("publisher_gid")
        if seq is None or not gid:
            return 0, 0, 0
        key = bytes(gid["data"])
        last = self._last.get(key)
        self._last[key] = seq if last is None else max(seq, last)
        self.last_before_match = 0
        if last is None and seq > 1 and self.is_new is not None and self.is_new(key):
            self.last_before_match = seq - 1
            self.before_match += seq - 1
        if last is None or seq <= last + 1:
            return 0, 0, 0
        missing = seq - last - 1
        self.total += missing
        return missing, last + 1, seq - 1
