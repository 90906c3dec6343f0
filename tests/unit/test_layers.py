"""pd_core's layers are in order: no module imports one from a layer above its own, and the
simulator loads no solver and no Gymnasium (ARCHITECTURE.md, "Layers, lowest first").

Every module of pd_core must be placed in `LAYER_OF`: a new module fails this test until it is,
which is where its author decides what it may import.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[2] / "pd_core" / "pd_core"

# lowest first; a module may import from its own layer and the layers below it
LAYERS = (
    "base",  # constants, dynamics, reward, envs, the braking law, Ray, small pure helpers
    "ocp",  # the optimal-control problem and its solvers
    "teachers",  # reference controllers and the receding-horizon OCP teachers
    "online",  # what flies: the runtime layer, and the simulator the node drives
    "episodes",  # the episode runner: any agent in the vector env
    "learning",  # demonstrations, DAgger labels, the DQN
    "experiments",  # evaluation reports, campaigns, sweeps, Ray
    "cli",  # console commands
)
PREFIX_LAYER = {
    "ocp": "ocp",
    "teachers": "teachers",
    "runtime": "online",
    "demonstrations": "learning",
    "dqn": "learning",
    "experiments": "experiments",
    "cli": "cli",
}
MODULE_LAYER = {
    **{
        m: "base"
        for m in (
            "actions",
            "commands",
            "config",
            "deprecation",
            "discretise",
            "dispersions",
            "disturbance",
            "dynamics",
            "env",
            "envelope",
            "jit",
            "lander",
            "lifecycle",
            "plots",
            "ray_session",
            "reward",
            "state",
            "ticker",
            "vector_env",
        )
    },
    "sim_pacing": "online",  # the simulator node's pacing and reset gate, without ROS
    "sim": "online",  # checks a start with the OCP's request rules (pd_core.ocp.request)
    "episodes": "episodes",
    "__init__": "cli",  # the public face: `load_policy` imports the runtime when called
}


def module_name(path: Path) -> str:
    rel = path.relative_to(PKG).with_suffix("")
    parts = [p for p in rel.parts if p != "__init__"] or ["__init__"]
    return ".".join(parts)


def layer_of(module: str) -> str:
    head = module.split(".", 1)[0]
    if head in PREFIX_LAYER and (PKG / head).is_dir():
        return PREFIX_LAYER[head]
    if module not in MODULE_LAYER:
        raise KeyError(f"pd_core.{module} is in no layer: place it in {__name__}.MODULE_LAYER")
    return MODULE_LAYER[module]


def imported_modules(path: Path) -> set[str]:
    """pd_core modules a file imports (at any depth: an import inside a function counts too)."""
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            # `from pd_core.x import y`: y is a module when a file or folder of that name exists
            base = node.module
            names = [
                f"{base}.{a.name}"
                if (PKG.parent / f"{base}.{a.name}".replace(".", "/")).with_suffix(".py").exists()
                or (PKG.parent / f"{base}.{a.name}".replace(".", "/")).is_dir()
                else base
                for a in node.names
            ]
        else:
            continue
        for n in names:
            if n == "pd_core":
                continue
            if n.startswith("pd_core."):
                out.add(n[len("pd_core.") :])
    return out


SOURCES = sorted(PKG.rglob("*.py"))


def test_every_module_has_a_layer():
    for path in SOURCES:
        layer_of(module_name(path))


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: module_name(p))
def test_no_module_imports_from_a_layer_above(path: Path):
    mine = LAYERS.index(layer_of(module_name(path)))
    above = {m: layer_of(m) for m in imported_modules(path) if LAYERS.index(layer_of(m)) > mine}
    assert above == {}, f"pd_core.{module_name(path)} ({LAYERS[mine]}) imports {above}"


def test_the_checker_sees_a_violation():
    # an episode-runner import from the DQN would be one: the checker must say so
    assert LAYERS.index(layer_of("dqn.train")) > LAYERS.index(layer_of("episodes"))
    assert "episodes" in imported_modules(PKG / "dqn" / "train.py")


@pytest.mark.parametrize("module", ["pd_core.sim", "pd_core.ocp", "pd_core.ocp.request"])
def test_the_simulator_and_the_ocp_package_load_no_solver_and_no_gymnasium(module: str):
    probe = f"import sys, {module}; print(' '.join(sorted(sys.modules)))"
    out = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, timeout=120, check=True
    )
    loaded = out.stdout.split()
    heavy = [m for m in loaded if m.split(".")[0] in {"scipy", "highspy", "gymnasium", "torch"}]
    assert heavy == [], heavy
    assert module in loaded


def test_the_ocp_package_names_load_on_first_use():
    import pd_core.ocp as ocp

    assert sorted(ocp.__all__) == sorted(ocp._HOME)
    for name in ocp.__all__:
        assert getattr(ocp, name) is not None
