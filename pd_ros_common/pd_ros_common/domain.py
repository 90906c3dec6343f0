"""A ROS domain of one's own: tests, demos and benches on one machine never hear each other.

A domain is claimed by an exclusive `flock` on `$TMPDIR/pd_ros_domains/<id>.lock`, held as long
as the returned file descriptor stays open (the claiming process's life). Ids run 1..101: 0 is
everyone's default, and above 101 FastDDS ports meet Linux's ephemeral range.
"""

from __future__ import annotations

import fcntl
import os
import tempfile
from pathlib import Path

DOMAIN_MIN, DOMAIN_MAX = 1, 101


def claim_domain_id(override_env: str | None = None) -> tuple[int, int | None]:
    """(domain id, fd of the held lock). `$<override_env>`, if set, is used as is (no lock)."""
    if override_env and os.environ.get(override_env):
        return int(os.environ[override_env]), None
    lock_dir = Path(tempfile.gettempdir()) / "pd_ros_domains"
    lock_dir.mkdir(mode=0o777, exist_ok=True)
    span = DOMAIN_MAX - DOMAIN_MIN + 1
    start = os.getpid() % span
    for i in range(span):
        domain = DOMAIN_MIN + (start + i) % span
        fd = os.open(lock_dir / f"{domain}.lock", os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            continue
        return domain, fd
    raise RuntimeError(f"no free ROS domain id in {DOMAIN_MIN}..{DOMAIN_MAX} (locks in {lock_dir})")
