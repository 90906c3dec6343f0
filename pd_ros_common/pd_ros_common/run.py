"""`main()` of a node: `--help`, one-line start-up errors, a clean stop on SIGINT and SIGTERM.

rclpy's own signal handlers shut the context down inside the handler, so whatever the node logs
while it stops ("decision time overall ...") fails with "publisher's context is invalid". Here
SIGINT and SIGTERM only set a flag; the executor is spun in short slices until it is set, and
the node stops (a managed node's shutdown transition, `destroy_node`) with its context still
valid. A managed node (`pd_ros_common.lifecycle.ManagedNode`) with `autostart` true is configured
and activated before the executor spins; a configure that fails is a start-up error. One of
an expected kind (a bad parameter, a bad model file) is one line on stderr and an exit status,
never a traceback. Once the node has stopped and logged, a DDS teardown that hangs (a known
failure class, e.g. eProsima/Fast-DDS#235; seen once here in CI on a loaded machine) cannot keep
the process alive: after `TEARDOWN_S` it says so in one line and exits with the same status.
The watchdog is armed before the shutdown transition, whose last log line also goes out over DDS
(/rosout). A hang that holds the GIL (a C call that never returns, seen once more in CI: the
node logged its last line and was SIGKILLed 10 s later without a word) stops a Python timer
too, so faulthandler backs it up from a C thread 50 % later (before a 10 s SIGKILL): it dumps
every thread's stack, to say where it hung, and exits with status 1.
"""

from __future__ import annotations

import faulthandler
import os
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

from pd_ros_common.lifecycle import ManagedNode, start_up
from pd_ros_common.node_help import node_help, wants_help
from pd_ros_common.params import ParameterError

TEARDOWN_S = 5.0  # executor shutdown, destroy_node and rclpy shutdown take well under 1 s


class _Watchdog:
    """Exits the process if the teardown outlives it; `cancel()` once the teardown is done."""

    def __init__(self, name: str, status: int) -> None:
        def _exit() -> None:
            print(
                f"{name}: DDS teardown took over {TEARDOWN_S:g} s; exiting anyway",
                file=sys.stderr,
                flush=True,
            )
            sys.stdout.flush()
            os._exit(status)

        self._timer = threading.Timer(TEARDOWN_S, _exit)
        self._timer.daemon = True
        self._timer.start()
        faulthandler.dump_traceback_later(1.5 * TEARDOWN_S, exit=True)  # no GIL needed

    def cancel(self) -> None:
        self._timer.cancel()
        faulthandler.cancel_dump_traceback_later()


def _exit_if_teardown_hangs(name: str, status: int) -> _Watchdog:
    return _Watchdog(name, status)


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
    status = 0
    try:
        node = make_node()
        if isinstance(node, ManagedNode) and getattr(node, "autostart", True):
            failure = start_up(node)
            if failure is not None:
                raise failure
        n = threads(node) if threads else 0
        executor = MultiThreadedExecutor(num_threads=n) if n > 0 else SingleThreadedExecutor()
        executor.add_node(node)
        while not stop.is_set() and rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except tuple(c for c, _ in codes) as exc:
        print(f"{name}: cannot start: {exc}", file=sys.stderr, flush=True)
        status = next(code for c, code in codes if isinstance(exc, c))
    finally:
        watchdog = _exit_if_teardown_hangs(name, status)
        if node is not None:
            if isinstance(node, ManagedNode) and status == 0:
                node.finish()
        if executor is not None:
            executor.shutdown(timeout_sec=1.0)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
        watchdog.cancel()
    return status
