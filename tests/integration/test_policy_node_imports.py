"""The policy node's flight path imports no optimal-control solver, scipy, HiGHS or Gymnasium."""

from __future__ import annotations

import subprocess
import sys

import pytest

pytestmark = [pytest.mark.integration]

HEAVY = ("scipy", "highspy", "gymnasium", "pd_core.ocp", "pd_core.teachers.mpc", "pd_core.env")


def test_the_policy_node_module_imports_nothing_heavy():
    probe = "import sys, pd_policy_node.node; print(' '.join(sorted(sys.modules)))"
    out = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, timeout=120, check=False
    )
    assert out.returncode == 0, out.stderr[-2000:]
    loaded = out.stdout.split()
    assert "rclpy" in loaded and "pd_core.runtime.layer" in loaded
    heavy = [m for m in loaded if any(m == h or m.startswith(h + ".") for h in HEAVY)]
    assert heavy == [], heavy  # (`pd_core.envelope`, the braking law, is not `pd_core.env`)
