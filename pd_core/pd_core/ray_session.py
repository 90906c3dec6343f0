"""Joining Ray: a local instance sized to this machine by default, or an existing cluster.

Only the Ray code paths (`pd-sweep`, `pd-eval --ray`, `pd-train --address`) import this module;
nothing else in pd_core needs Ray. It sits low (it imports nothing of pd_core) so that
the demonstrations and the campaigns share it.
"""

from __future__ import annotations

import logging
import os
import socket
from collections.abc import Callable, Sequence
from typing import Any
from urllib.parse import urlsplit

import ray  # optional heavy dependency: imported only by the Ray code paths

CONNECT_TIMEOUT_S = 3.0
MAX_RETRIES = 3  # attempts after a worker dies (Ray's own retry of system failures)


class RayUnavailable(RuntimeError):
    """Ray could not be started or joined; the message is one line for the user."""


def connect(address: str | None = None, num_cpus: int | None = None) -> Any:
    """Start a local Ray instance (`address` None, "" or "local"; `num_cpus` default: all of
    this machine's) or join a cluster (`auto`, `host:port`, `ray://host:port`). Quiet logs.
    Reuses a session this process already has. Returns the `ray` module."""
    if ray.is_initialized():
        return ray
    quiet = {"logging_level": logging.ERROR, "log_to_driver": False}
    local = not address or address == "local"
    try:
        if local:
            # Ray gives its raylet a fixed 30 s to register; a machine loaded far beyond its
            # cores can miss that (then this fails, and retrying would leak Ray's processes).
            ray.init(
                num_cpus=num_cpus or os.cpu_count() or 1,
                include_dashboard=False,
                configure_logging=True,
                **quiet,
            )
        else:
            _check_reachable(address)
            ray.init(address=address, **quiet)
    except RayUnavailable:
        raise
    except Exception as exc:  # noqa: BLE001 - ray raises many types; the user needs one line
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        where = "cannot start a local Ray instance" if local else f"cannot join {address}"
        raise RayUnavailable(f"{where}: {first}{_HINT}") from exc
    return ray


_HINT = (
    " (start one with `ray start --head` and pass --address auto, or omit --address for a local"
    " instance)"
)


def _check_reachable(address: str) -> None:
    """Fail fast, in one line, when host:port of `address` does not accept connections."""
    if address == "auto":
        return  # ray looks for a local cluster itself and says so quickly when there is none
    parts = urlsplit(address if "://" in address else f"tcp://{address}")
    try:
        host, port = parts.hostname, parts.port
    except ValueError as exc:
        raise RayUnavailable(f"bad Ray address {address!r}: {exc}{_HINT}") from exc
    if not host or not port:
        raise RayUnavailable(
            f"bad Ray address {address!r}: expected auto, host:port or ray://host:port{_HINT}"
        )
    try:
        socket.create_connection((host, port), timeout=CONNECT_TIMEOUT_S).close()
    except OSError as exc:
        reason = exc.strerror or str(exc) or type(exc).__name__
        raise RayUnavailable(
            f"no Ray cluster at {address}: {host}:{port} is not reachable ({reason}){_HINT}"
        ) from exc


def cluster_cpus() -> int:
    """CPUs of the Ray session (after `connect`)."""
    return max(1, int(ray.cluster_resources().get("CPU", 1)))


def map_tasks(
    fn: Callable[..., Any], tasks: Sequence[tuple], address: str, max_retries: int = MAX_RETRIES
) -> list[Any]:
    """fn(*task) for every task as one Ray task each (one CPU), results in task order, after
    `connect(address)` ("local": a local instance). A task whose worker dies is retried by Ray.
    RayUnavailable if Ray cannot be started or joined."""
    connect(address)
    remote = ray.remote(num_cpus=1, max_retries=max_retries)(fn)
    return ray.get([remote.remote(*t) for t in tasks])
