"""Publishing a burst on a RELIABLE topic without losing a message at the writer.

A RELIABLE KEEP_LAST writer whose history is full of samples some reader has not acknowledged
waits for that reader up to its `max_blocking_time` (Fast DDS: 100 ms) and then fails the write:
rclpy raises `RCLError` ("cannot publish data"), and the message is not sent. A busy reader, on a
loaded machine, is late by more than that. `publish_acked` waits until the readers acknowledge
what is queued (`wait_for_all_acked`) and writes again, so a burst goes out whole or the call
says, after `timeout_s`, that it could not.
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
