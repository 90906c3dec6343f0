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
from rclpy.client import Client
from rclpy.context import Context
from rclpy.executors import Executor, SingleThreadedExecutor
from rclpy.node import Node


def spin_until(
    executor: Executor,
    predicate: Callable[[], bool],
    timeout_s: float,
    check: Callable[[], None] | None = None,
    step_s: float = 0.05,
) -> bool:
    """Spin `executor` in `step_s` slices until `predicate()` or the deadline; `check()` may
    raise (a child died). Shared with the integration tests' `spin_until` fixture."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        if check is not None:
            check()
        executor.spin_once(timeout_sec=step_s)
    return bool(predicate())


# A service's response goes out on a writer that must have matched the client's response reader;
# the client only sees the server's request reader (`service_is_ready`). Until the server has
# discovered the client too, Fast DDS drops the response after a short wait (rclpy warns "failed
# to send response (timeout)") and the request is never answered: a fresh client on a busy
# machine lost one so (CI, test_ocp_node). Spinning this long after `service_is_ready` lets
# discovery finish both ways.
SERVICE_SETTLE_S = 1.0


def wait_for_server(
    executor: Executor, client: Client, timeout_s: float, settle_s: float = SERVICE_SETTLE_S
) -> bool:
    """True once `client` sees its server (within `timeout_s`), after `settle_s` more of
    spinning so the server has matched the client's response reader as well."""
    if not spin_until(executor, client.service_is_ready, timeout_s):
        return False
    spin_until(executor, lambda: False, settle_s)
    return True


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
        return spin_until(self.executor, predicate, timeout_s, check)

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
