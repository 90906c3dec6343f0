"""Publishing a burst on a RELIABLE topic without losing a message at the writer.

Under load, rmw_fastrtps can refuse a write: rclpy raises `RCLError` ("cannot publish data") and
the message is not sent. CI saw it once, at message 1449 of 2000 published back to back to a
busy simulator (depth 1000); a stopped or slow reader alone does not cause it here (a KEEP_LAST
writer drops its oldest sample instead), so the trigger is in Fast DDS's writer resources, not
pinned down. `publish_acked` retries: after a refused write it waits until the readers
acknowledge what is queued (`wait_for_all_acked`, at most `ACK_WAIT_S`) and writes again, so a
burst goes out whole, or the call says after `timeout_s` that it could not.
"""

from __future__ import annotations

import time
from typing import Any

from rclpy._rclpy_pybind11 import RCLError
from rclpy.duration import Duration
from rclpy.publisher import Publisher

ACK_WAIT_S = 1.0


class PublishTimeout(RuntimeError):
    """The readers acknowledged nothing for `timeout_s`: the message was not sent."""


def publish_acked(pub: Publisher, msg: Any, timeout_s: float = 30.0) -> int:
    """Publish `msg`; while the writer's history is full, wait for acknowledgements and retry.
    Returns the number of writes that failed before the one that went out; raises
    `PublishTimeout` after `timeout_s` of failures."""
    deadline = time.monotonic() + timeout_s
    failed = 0
    while True:
        try:
            pub.publish(msg)
            return failed
        except RCLError as exc:
            failed += 1
            if time.monotonic() >= deadline:
                raise PublishTimeout(
                    f"{pub.topic_name}: not sent after {failed} tries in {timeout_s:.0f} s ({exc})"
                ) from exc
            pub.wait_for_all_acked(Duration(seconds=ACK_WAIT_S))
