"""Suite-wide hang guard: a test stuck in C code ends the run in minutes, with every stack.

pytest-timeout (``timeout`` in pyproject.toml, ``@pytest.mark.timeout`` per test) stops a test
with SIGALRM, whose Python handler runs only when the main thread next executes bytecode. A
thread blocked inside C (a DDS participant that never returns, a deadlocked mutex) never does,
and the suite then hangs until CI kills it, printing nothing about where.

So wherever pytest-timeout sets a test's timer (its `pytest_timeout_set_timer` hook), this also
arms ``faulthandler.dump_traceback_later`` (a C watchdog thread, no GIL needed) for that timeout
plus ``GRACE_S``: past that, the tracebacks of all threads go to the terminal's stderr and the
process exits with status 1. The watchdog is cancelled with the plugin's timer, so it fires only
when pytest-timeout could not.
"""

from __future__ import annotations

import faulthandler
import os

import pytest

GRACE_S = 60.0  # after the test's own timeout, before the watchdog gives up on it

_stderr_fd: int | None = None


def pytest_timeout_set_timer(item: pytest.Item, settings) -> None:
    """pytest-timeout's hook, with its settings for this test (marker, option or ini); returning
    None lets the plugin's own SIGALRM timer be set as well."""
    global _stderr_fd
    if _stderr_fd is None:
        # Output capture is suspended around the runtest protocol, so fd 2 is the terminal (or
        # CI log) here, not the temporary file a test's output goes to and os._exit would lose.
        _stderr_fd = os.dup(2)
    faulthandler.dump_traceback_later(settings.timeout + GRACE_S, exit=True, file=_stderr_fd)


def pytest_timeout_cancel_timer(item: pytest.Item) -> None:
    faulthandler.cancel_dump_traceback_later()
