"""Helpers for integration tests that run the nodes as real processes (see conftest.py for the
ROS domain and the in-process rclpy fixtures).

Every process is started in its own session (process group) with the test's environment (so the
ROS_DOMAIN_ID claimed by conftest.py), logs to a file, and is stopped by `ProcessSet.stop_all`
(SIGINT, then SIGKILL of the whole group) in a `finally`.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from pd_core.config import TABLE3

ROOT = Path(__file__).resolve().parents[2]


def executable(package: str, name: str) -> str:
    """Installed ament_python entry point <prefix>/lib/<package>/<name> (where ros2 run looks)."""
    for prefix in filter(None, os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)):
        path = Path(prefix) / "lib" / package / name
        if path.is_file() and os.access(path, os.X_OK):
            return str(path)
    raise FileNotFoundError(
        f"{package}/{name} not installed under $AMENT_PREFIX_PATH/lib/{package} (run make setup)"
    )


def ros_args(params: dict[str, Any] | None = None, remaps: dict[str, str] | None = None) -> list:
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


class NodeProcess:
    """One child process in its own process group, output to a log file."""

    def __init__(self, name: str, argv: list[str], log_dir: Path, env: dict | None = None):
        self.name = name
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

    def log(self) -> str:
        return self.log_path.read_text(errors="replace")

    def wait_log(self, text: str, timeout_s: float) -> bool:
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

    def stop(self, timeout_s: float = 5.0, sig: int = signal.SIGINT) -> int | None:
        """SIGINT (or `sig`), wait, then SIGKILL the group; returns the exit status."""
        if self.alive:
            self.signal_group(sig)
            try:
                self.proc.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.signal_group(signal.SIGKILL)
                self.proc.wait(5.0)
        self.signal_group(signal.SIGKILL)  # stragglers of the group, if any
        self._log.close()
        return self.proc.returncode


class ProcessSet:
    """Processes started by a test or module; `stop_all` in a finally stops each of them."""

    def __init__(self, log_dir: Path) -> None:
        self.log_dir = log_dir
        self.procs: list[NodeProcess] = []

    def start(self, name: str, argv: list[str], env: dict | None = None) -> NodeProcess:
        p = NodeProcess(name, argv, self.log_dir, env)
        self.procs.append(p)
        return p

    def node(
        self,
        package: str,
        params: dict[str, Any] | None = None,
        remaps: dict[str, str] | None = None,
        name: str | None = None,
    ) -> NodeProcess:
        argv = [executable(package, package), *ros_args(params, remaps)]
        return self.start(name or package, argv)

    def stop_all(self) -> None:
        for p in reversed(self.procs):
            p.stop()

    def logs(self) -> str:
        return "\n".join(f"===== {p.name} ({p.log_path})\n{p.log()[-4000:]}" for p in self.procs)


def make_model(path: Path, seed: int = 0) -> Path:
    """An untrained (random) policy file: tests do not depend on the shipped model."""
    import torch

    from pd_core.dqn.network import QNetwork
    from pd_core.policy import save_policy

    torch.manual_seed(seed)
    return save_policy(path, QNetwork(), {"note": "untrained, for tests"})


def offline_rollout(model: Path, seed: int, initial_state: np.ndarray) -> list[np.ndarray]:
    """States [s0, s1, ...] of the pd_core rollout the simulator node must reproduce."""
    import pd_core
    from pd_core.env import PoweredDescentEnv

    policy = pd_core.load_policy(model)
    env = PoweredDescentEnv(disturbance=True)
    _, info = env.reset(seed=seed, options={"initial_state": initial_state})
    states = [info["state"]]
    while True:
        _, _, term, trunc, info = env.step(policy.act(info["state"]))
        states.append(info["state"])
        if term or trunc:
            return states


def table3_state(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.uniform(TABLE3.lo, TABLE3.hi)


def wait_for(predicate: Callable[[], bool], timeout_s: float, step_s: float = 0.05) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(step_s)
    return bool(predicate())
