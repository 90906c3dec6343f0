"""Wall-clock timing of the real-time simulator: a fixed-rate ticker and latency percentiles."""

from __future__ import annotations

import math
import os
import threading
import time
from collections.abc import Callable

import numpy as np


class FixedRateTicker:
    """Calls `fn()` every `period_s` on a thread, at absolute monotonic deadlines (no drift).

    A call that overruns skips the deadlines it missed (counted in `skipped`) instead of
    bursting. `lateness_s` keeps how late each call started (the wake-up jitter).
    """

    def __init__(
        self,
        period_s: float,
        fn: Callable[[], None],
        name: str = "ticker",
        keep: int = 10000,
        priority: int = 0,
    ) -> None:
        if not (math.isfinite(period_s) and period_s > 0):
            raise ValueError(f"period must be positive and finite, got {period_s!r}")
        self.period_s = period_s
        self._fn = fn
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._keep = keep
        self.lateness_s: list[float] = []
        self.skipped = 0
        self.error: BaseException | None = None
        # > 0: run the ticker thread under SCHED_FIFO at this priority (Linux; needs
        # CAP_SYS_NICE). Wake-ups then do not wait behind other busy processes.
        self.priority = priority
        self.priority_error: str | None = None

    def start(self) -> None:
        self._thread.start()

    def stop(self, join: bool = True, timeout_s: float = 2.0) -> None:
        """Stop ticking; `join=False` only asks (safe under a lock that `fn` takes)."""
        self._stop.set()
        if join and self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout_s)

    def _run(self) -> None:
        if self.priority > 0:
            try:
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(self.priority))
            except (AttributeError, OSError) as exc:
                self.priority_error = f"SCHED_FIFO {self.priority} refused: {exc}"
        deadline = time.monotonic() + self.period_s
        while not self._stop.is_set():
            delay = deadline - time.monotonic()
            if delay > 0:
                # time.sleep uses clock_nanosleep on Linux; Event.wait would add its own slack.
                time.sleep(delay)
                if self._stop.is_set():
                    break
            now = time.monotonic()
            self.lateness_s.append(now - deadline)
            if len(self.lateness_s) > self._keep:
                del self.lateness_s[: len(self.lateness_s) - self._keep]
            try:
                self._fn()
            except BaseException as exc:  # keep the error for the owner; stop ticking
                self.error = exc
                return
            deadline += self.period_s
            now = time.monotonic()
            if now > deadline:
                missed = math.floor((now - deadline) / self.period_s) + 1
                self.skipped += missed
                deadline += missed * self.period_s


def percentiles_ms(samples_s: list[float] | np.ndarray, qs: tuple[float, ...] = (50, 99)) -> dict:
    """{"n", "p50", "p99", "max"} of samples in seconds, reported in milliseconds."""
    a = np.asarray(samples_s, dtype=float) * 1e3
    if a.size == 0:
        return {"n": 0, **{f"p{q:g}": math.nan for q in qs}, "max": math.nan}
    out: dict[str, float] = {"n": int(a.size)}
    for q in qs:
        out[f"p{q:g}"] = float(np.percentile(a, q))
    out["max"] = float(a.max())
    return out
