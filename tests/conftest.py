"""Suite-wide hang guard: a test stuck in C code ends the run in minutes, with every stack.

pytest-timeout (``timeout`` in pyproject.toml, ``@pytest.mark.timeout`` per test) stops a test
with SIGALRM, whose Python handler runs only when the main thread next executes bytecode. A
thread blocked inside C (a DDS participant that never returns, a deadlocked mutex) never does,
and the suite then hangs until CI kills it, printing nothing about where.

So each test also arms ``faulthandler.dump_traceback_later`` (a C watchdog thread, no GIL
needed) for its own timeout plus ``GRACE_S``: past that, the tracebacks of all threads go to the
terminal's stderr and the process exits with status 1. The watchdog is cancelled when the test
ends, so it fires only when pytest-timeout could not.
"""

from __future__ import annotations

import faulthandler
import os

import pytest

GRACE_S = 60.0  # after the test's own timeout, before the watchdog gives up on it

_stderr_fd: int | None = None


def _timeout_s(item: pytest.Item) -> float:
    marker = item.get_closest_marker("timeout")
    if marker is not None and marker.args:
        return float(marker.args[0])
    if marker is not None and "timeout" in marker.kwargs:
        return float(marker.kwargs["timeout"])
    option = item.config.getoption("timeout", None)  # pytest-timeout's --timeout
    return float(option if option is not None else item.config.getini("timeout") or 0.0)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None):
    global _stderr_fd
    timeout = _timeout_s(item)
    if timeout <= 0:
        return (yield)
    if _stderr_fd is None:
        # Output capture is suspended between tests, so fd 2 is the terminal (or CI log) here,
        # not the temporary file that a test's output goes to and that os._exit would lose.
        _stderr_fd = os.dup(2)
    faulthandler.dump_traceback_later(timeout + GRACE_S, exit=True, file=_stderr_fd)
    try:
        return (yield)
    finally:
        faulthandler.cancel_dump_traceback_later()
