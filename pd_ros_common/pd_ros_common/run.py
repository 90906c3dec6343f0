"""`main()` of a node: `--help`, one-line start-up errors, a clean stop on SIGINT and SIGTERM.

rclpy's own signal handlers shut the context down inside the handler, so whatever the node logs
while it stops ("decision time overall ...") fails with "publisher's context is invalid". Here
SIGINT and SIGTERM only set a flag; the executor is spun in short slices until it is set, and
the node stops (`on_shutdown`, `destroy_node`) with its context still valid. A start-up error of
an expected kind (a bad parameter, a bad model file) is one line on stderr and an exit status,
never a traceback.
"""

from __future__ import annotations

import signal
import sys
import threading
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import rclpy
from rclpy.executors import (
    ExternalShutdownException,
    MultiThreadedExecutor,
    SingleThreadedExecutor,
)
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from pd_ros_common.node_help import node_help, wants_help
from pd_ros_common.params import ParameterError


def run_node(
    name: str,
    doc: str,
    parameters: Mapping[str, Sequence[Any]],
    make_node: Callable[[], Node],
    args: list[str] | None = None,
    *,
    threads: Callable[[Node], int] | None = None,
    exit_codes: Sequence[tuple[type[BaseException], int]] = (),
) -> int:
    """Run the node made by `make_node` until SIGINT/SIGTERM; the process's exit status.

    `threads(node)` > 0 spins a MultiThreadedExecutor with that many threads. `exit_codes` maps
    start-up exceptions to exit statuses (ParameterError is 2); they are reported in one line.
    """
    argv = sys.argv[1:] if args is None else args
    if wants_help(argv):
        print(node_help(name, name, doc, parameters))
        return 0
    codes = [*exit_codes, (ParameterError, 2)]
    stop = threading.Event()
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    node = executor = None
    try:
        node = make_node()
        n = threads(node) if threads else 0
        executor = MultiThreadedExecutor(num_threads=n) if n > 0 else SingleThreadedExecutor()
        executor.add_node(node)
        while not stop.is_set() and rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except tuple(c for c, _ in codes) as exc:
        print(f"{name}: cannot start: {exc}", file=sys.stderr, flush=True)
        return next(code for c, code in codes if isinstance(exc, c))
    finally:
        if node is not None:
            on_shutdown = getattr(node, "on_shutdown", None)
            if on_shutdown is not None:
                on_shutdown()
        if executor is not None:
            executor.shutdown(timeout_sec=1.0)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0
