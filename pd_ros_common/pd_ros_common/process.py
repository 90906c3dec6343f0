"""Nodes and tools as child processes: start, watch, stop (the demo, the tests and the soak bench).

Every child runs in its own session (process group) with the caller's environment, writes its
output to a log file, and is stopped with SIGINT (or another signal), then SIGKILL of the whole
group after a deadline. `Supervisor.stop_all` in a `finally` stops every child it started.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any


class ProcessError(RuntimeError):
    """A child is missing or died; the message says which and ends with its log's tail."""


def executable(package: str, name: str) -> str:
    """Installed entry point <prefix>/lib/<package>/<name> on AMENT_PREFIX_PATH (`ros2 run`)."""
    for prefix in filter(None, os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)):
        path = Path(prefix) / "lib" / package / name
        if path.is_file() and os.access(path, os.X_OK):
            return str(path)
    raise ProcessError(
        f"{package}/{name} is not installed under $AMENT_PREFIX_PATH/lib/{package} "
        "(run `make setup`, then `source env.sh`)"
    )


def ros_args(
    params: Mapping[str, Any] | None = None, remaps: Mapping[str, str] | None = None
) -> list[str]:
    """`--ros-args -p k:=v ... -r from:=to ...` (bools lower-case, lists of floats)."""
    out = ["--ros-args"]
    for k, v in (params or {}).items():
        if isinstance(v, bool):
            v = "true" if v else "false"
        elif isinstance(v, (list, tuple)):
            v = "[" + ", ".join(repr(float(x)) for x in v) + "]"
        out += ["-p", f"{k}:={v}"]
    for k, v in (remaps or {}).items():
        out += ["-r", f"{k}:={v}"]
    return out


def wait_for(predicate: Callable[[], bool], timeout_s: float, step_s: float = 0.05) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(step_s)
    return bool(predicate())


class Child:
    """One child process in its own process group, output to `<log_dir>/<name>.log`."""

    def __init__(
        self, name: str, argv: list[str], log_dir: Path, env: Mapping[str, str] | None = None
    ) -> None:
        self.name = name
        log_dir.mkdir(parents=True, exist_ok=True)
        self.log_path = log_dir / f"{name}.log"
        if self.log_path.exists():  # a restarted node keeps its predecessor's log
            self.log_path = log_dir / f"{name}-{time.monotonic_ns()}.log"
        self._log = open(self.log_path, "wb")  # noqa: SIM115 (closed in stop)
        self.proc = subprocess.Popen(
            argv,
            stdout=self._log,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            start_new_session=True,
            env={**os.environ, "PYTHONUNBUFFERED": "1", **(env or {})},
        )

    @property
    def alive(self) -> bool:
        return self.proc.poll() is None

    @property
    def pid(self) -> int:
        return self.proc.pid

    def log(self) -> str:
        return self.log_path.read_text(errors="replace")

    def tail(self, n: int = 15) -> str:
        return "\n".join(f"    {line}" for line in self.log().splitlines()[-n:])

    def wait_log(self, text: str, timeout_s: float) -> bool:
        """True once `text` is in the log (False at the deadline or when the child exits)."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if text in self.log():
                return True
            if not self.alive:
                return text in self.log()
            time.sleep(0.05)
        return False

    def signal_group(self, sig: int) -> None:
        try:
            os.killpg(self.proc.pid, sig)
        except ProcessLookupError:
            pass

    def stop(self, timeout_s: float = 10.0, sig: int = signal.SIGINT) -> int | None:
        """`sig` to the group, wait, then SIGKILL the group; the exit status."""
        if self.alive:
            self.signal_group(sig)
            try:
                self.proc.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.signal_group(signal.SIGKILL)
                self.proc.wait(5.0)
        self.signal_group(signal.SIGKILL)  # stragglers of the group (solver processes)
        if not self._log.closed:
            self._log.close()
        return self.proc.returncode


class Supervisor:
    """The children of one run: start them, check they live, stop them all."""

    def __init__(self, log_dir: Path, env: Mapping[str, str] | None = None) -> None:
        self.log_dir = log_dir
        self.env = dict(env or {})
        self.children: list[Child] = []

    def start(self, name: str, argv: list[str]) -> Child:
        child = Child(name, argv, self.log_dir, self.env)
        self.children.append(child)
        return child

    def node(
        self,
        package: str,
        params: Mapping[str, Any] | None = None,
        remaps: Mapping[str, str] | None = None,
        name: str | None = None,
        executable_name: str | None = None,
        extra: list[str] | None = None,
    ) -> Child:
        """`<package>/<executable_name or package> [extra] --ros-args -p ... -r ...`."""
        exe = executable(package, executable_name or package)
        return self.start(name or package, [exe, *(extra or []), *ros_args(params, remaps)])

    def check_alive(self) -> None:
        """ProcessError if a child has exited (with its log's tail)."""
        for c in self.children:
            if not c.alive:
                raise ProcessError(f"{c.name} exited ({c.proc.returncode}):\n{c.tail()}")

    def stop_all(self, first: str | None = None) -> None:
        """Stop every child, `first` (a name) before the others, the rest newest first."""
        order = sorted(reversed(self.children), key=lambda c: c.name != first)
        for c in order:
            c.stop()

    def logs(self, chars: int = 4000) -> str:
        parts = [f"===== {c.name} ({c.log_path})\n{c.log()[-chars:]}" for c in self.children]
        return "\n".join(parts)
