"""The flight path is light: loading and flying a policy file imports no optimal-control, scipy,
HiGHS or Gymnasium module, and a decision never touches torch (it only reads the weights). The
builder (`pd_core.runtime.build`) names every controller without loading a solver: an MPC
teacher's solvers load when one is built."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROBUST = Path(__file__).resolve().parents[3] / "models" / "pd_dqn_robust"
HEAVY = ("scipy", "highspy", "gymnasium", "pd_core.ocp", "pd_core.teachers.mpc", "pd_core.env")

PROBE = f"""
import sys, types
import numpy as np
from pd_core.runtime.build import build

rt = build({str(ROBUST)!r}).runtime
law = build("controller:zemzev-vernier", as_runtime=True).runtime

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
rt.bare_action(s)
law.begin_episode()
law.step(s)
print(" ".join(sorted(sys.modules)))
"""
LIGHT = "import sys, pd_core.runtime, pd_core.runtime.build; print(' '.join(sorted(sys.modules)))"


def loaded_by(probe: str) -> list[str]:
    out = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, timeout=120, check=False
    )
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout.split()


def heavy_in(loaded: list[str]) -> list[str]:
    return [m for m in loaded if any(m == h or m.startswith(h + ".") for h in HEAVY)]


def test_flying_a_policy_file_loads_no_solver_and_never_calls_torch():
    loaded = loaded_by(PROBE)
    assert heavy_in(loaded) == []
    assert "pd_core.runtime.layer" in loaded and "pd_core.teachers.zemzev" in loaded
    assert "pd_core.envelope" in loaded  # the braking law, compiled into the layer
    assert "pd_core.teachers.registry" in loaded  # the builder names controllers: no solver


def test_importing_the_runtime_and_its_builder_loads_no_torch():
    loaded = loaded_by(LIGHT)
    assert heavy_in(loaded) == [] and "torch" not in loaded


def test_an_mpc_teacher_loads_its_solvers_when_it_is_built():
    loaded = loaded_by(
        "import sys; from pd_core.runtime.build import build; build('controller:mpc-fuel'); "
        "print(' '.join(sorted(sys.modules)))"
    )
    assert "pd_core.teachers.mpc" in loaded and "highspy" in loaded
