"""The flight path is light: loading and flying a policy file imports no optimal-control, scipy,
HiGHS or Gymnasium module, and a decision never touches torch (it only reads the weights)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROBUST = Path(__file__).resolve().parents[2] / "models" / "pd_dqn_robust"
HEAVY = ("scipy", "highspy", "gymnasium", "pd_core.ocp", "pd_core.teachers.mpc", "pd_core.env")

PROBE = f"""
import sys, types
import numpy as np
from pd_core.runtime import load_policy

rt = load_policy({str(ROBUST)!r})

class Poisoned(types.ModuleType):
    def __getattr__(self, name):
        raise AssertionError(f"a decision used torch.{{name}}")

sys.modules["torch"] = Poisoned("torch")  # any torch use from here on fails loudly
rt.begin_episode()
s = np.array([300.0, -200.0, 2000.0, -20.0, 10.0, -70.0, 2000.0])
for _ in range(50):
    a, d = rt.step(s)
    s = s + np.array([0, 0, -14.0, 0, 0, 0, -1.0])
rt.begin_episodes(8)
rt.step_rows(np.tile(s, (8, 1)), np.arange(8))
print(" ".join(sorted(sys.modules)))
"""


def test_flying_a_policy_file_loads_no_solver_and_never_calls_torch():
    out = subprocess.run(
        [sys.executable, "-c", PROBE], capture_output=True, text=True, timeout=120, check=False
    )
    assert out.returncode == 0, out.stderr[-2000:]
    loaded = out.stdout.split()
    heavy = [m for m in loaded if any(m == h or m.startswith(h + ".") for h in HEAVY)]
    assert heavy == [], heavy
    assert "pd_core.runtime.layer" in loaded and "pd_core.teachers.zemzev" in loaded
    assert "pd_core.envelope" in loaded  # the braking law, compiled into the layer
