"""A node of one's own, outside the stack's processes: for tools and benches that drive the stack.

It owns its rclpy context (so it never touches the global one a caller may hold), spins its own
executor in short slices (never a bare spin), and tears all of it down in one `close()`, in the
order rclpy needs: node out of the executor, node destroyed, executor, then context.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from types import TracebackType

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node


class RosSession:
    """`node` on `executor` on a `context` of its own, on `domain_id` (None: ROS_DOMAIN_ID)."""

    def __init__(self, name: str, domain_id: int | None = None, namespace: str = "/") -> None:
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = Node(name, namespace=namespace, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def spin_once(self, timeout_s: float = 0.05) -> None:
        self.executor.spin_once(timeout_sec=timeout_s)

    def spin_for(self, duration_s: float) -> None:
        """Deliver whatever arrives for `duration_s` (to let messages in flight land)."""
        end = time.monotonic() + duration_s
        while time.monotonic() < end:
            self.spin_once()

    def spin_until(
        self,
        predicate: Callable[[], bool],
        timeout_s: float,
        check: Callable[[], None] | None = None,
    ) -> bool:
        """Spin until `predicate()` or the deadline; `check()` may raise (a child died)."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if predicate():
                return True
            if check is not None:
                check()
            self.spin_once()
        return bool(predicate())

    def close(self) -> None:
        self.executor.remove_node(self.node)
        self.node.destroy_node()
        self.executor.shutdown(timeout_sec=1.0)
        self.context.try_shutdown()

    def __enter__(self) -> RosSession:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
