"""One way to build what flies: `build(spec)` makes the actor that the policy node, `pd-eval`,
campaigns, benches and tests fly, from a policy file, the shipped one, or a reference controller
(`pd_core.teachers.registry`), with or without the runtime layer.

A spec is a path, a string (the syntax of `pd-eval` and campaigns) or a factory:

    FILE                     a policy file behind the runtime config it pins (a `Path` is
                             always a file, never parsed as below)
    ""                       the shipped policy file (`shipped_policy`), likewise
    bare:FILE                the network alone (`RuntimeConfig.off()`)
    layer:FILE               the network behind the code's default config (`RuntimeConfig()`)
    controller:NAME          the reference controller alone, no `Runtime` (so is
                             bare:controller:NAME)
    layer:controller:NAME    the reference controller behind the default config
    set:K=V[,K=V...]:SPEC    SPEC, which must have a layer, with those `RuntimeConfig` settings
                             changed (`RuntimeConfig.with_settings`)
    a callable               spec() is the actor, as it is made (a picklable one crosses to
                             Ray)

``shield:`` is the old name of ``layer:`` (deprecated: it flies the same and warns once,
`pd_core.deprecation`).

`build`'s keywords say the same for a caller that holds the parts (the policy node's
parameters): `layer` ("file", "always", "never") is the ``layer:``/``bare:`` prefix, `settings`
a ``set:`` around the whole, and `as_runtime=True` puts an actor built without a layer behind
`RuntimeConfig.off()`, so that what comes back is always a `Runtime`.

The shipped file is found where the policy node has always looked (`shipped_policy`): the
environment variable `PD_MODEL_PATH`, else `$PD_ROOT/models/...` (`env.sh` sets `PD_ROOT`), else
the source tree this module runs from. What cannot be built is refused with `PolicyLoadError`
(a `ValueError`) in one line: a missing or mismatched file, an unknown controller, a bad runtime
setting, or settings for an actor without a layer.

Imports the registry of controllers, which loads no solver (an MPC teacher's solvers load when
one is built), and torch only to read a file's weights (`load_policy`).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

from pd_core.deprecation import renamed
from pd_core.runtime.config import RuntimeConfig
from pd_core.runtime.layer import Actor, Runtime
from pd_core.runtime.policy_file import (
    SHIPPED_POLICY,
    PolicyLoadError,
    check_layer_mode,
    load_policy,
)
from pd_core.teachers.registry import make_controller

AgentSpec = str | Path | Callable[[], Actor | Runtime]
"""What `build` takes: a policy file's path, a spec string (module docstring) or a factory
returning an actor (a `Runtime`, or an actor that flies alone)."""
MODEL_ENV = "PD_MODEL_PATH"
"""Environment variable naming the shipped policy file (`shipped_policy`)."""
ROOT_ENV = "PD_ROOT"
"""Environment variable naming the repository root, set by env.sh (`shipped_policy`)."""
CONTROLLER = "controller:"
# spec prefix -> `load_policy`'s layer mode; "shield:" the old name of "layer:" (deprecated)
_MODES = {"bare:": "never", "layer:": "always", "shield:": "always"}
_RENAMED = {"shield:": "layer:"}


@dataclass(frozen=True)
class Built:
    """What `build` made: the actor that flies and how to name it."""

    actor: Actor | Runtime
    """a `Runtime` (a policy file; a controller behind a layer), or a controller alone"""
    label: str
    """short name: the policy file's stem, "controller NAME" (+ " + layer"), a factory's
    name; " (K=V,...)" added for runtime settings changed"""
    policy_file: Path | None = None
    """the policy file flown (None: a controller or a factory)"""
    settings: str = ""
    """the runtime settings changed (K=V,K=V; "" none)"""

    @property
    def runtime(self) -> Runtime:
        """The actor as a `Runtime`; PolicyLoadError if it flies without one (build it with
        `as_runtime=True`)."""
        if not isinstance(self.actor, Runtime):
            raise PolicyLoadError(f"{self.label} flies without a runtime layer")
        return self.actor

    def describe(self) -> str:
        """One line on what flies (the policy node logs it when it is ready): the file with its
        network and code version, or the reference controller; the runtime settings changed;
        whether the layer is on, and its config's digest."""
        rt = self.actor if isinstance(self.actor, Runtime) else None
        if self.policy_file is not None and rt is not None:
            meta = rt.metadata
            head = (
                f"{self.policy_file} (network {meta['network']['hidden']}, "
                f"{rt.actions.n} actions, code {meta.get('code_version', '?')}"
            )
        else:
            head = f"reference controller {getattr(self.actor, 'name', self.label)} ("
        parts = [head]
        if self.settings:
            parts.append(f"runtime settings {self.settings}")
        if rt is None:
            parts.append("no runtime layer")
        else:
            parts.append("no runtime layer" if rt.config.is_off else "runtime layer on")
            parts.append(f"config {rt.config.digest()}")
        return ", ".join(parts) + ")"


def shipped_policy() -> Path:
    """The shipped policy file: `$PD_MODEL_PATH` if set; else the first of
    `$PD_ROOT/<SHIPPED_POLICY>` and `<SHIPPED_POLICY>` in a folder above this module (the
    source tree) that exists; else the first of those (for the message that it is missing)."""
    if os.environ.get(MODEL_ENV):
        return Path(os.environ[MODEL_ENV])
    candidates: list[Path] = []
    if os.environ.get(ROOT_ENV):
        candidates.append(Path(os.environ[ROOT_ENV]) / SHIPPED_POLICY)
    candidates += [parent / SHIPPED_POLICY for parent in Path(__file__).resolve().parents]
    return next((c for c in candidates if c.is_file()), candidates[0])


def build(
    spec: AgentSpec = "", *, layer: str = "file", settings: str = "", as_runtime: bool = False
) -> Built:
    """What flies for `spec` (module docstring; "" the shipped policy file), with the runtime
    layer of `layer` ("file": as the spec says; "always" as ``layer:``; "never" as ``bare:``; a
    prefix in the spec wins), the runtime `settings` changed (as ``set:settings:SPEC``), and,
    with `as_runtime`, an actor built without a layer put behind `RuntimeConfig.off()` (its
    settings then change that config). PolicyLoadError in one line if it cannot be built."""
    check_layer_mode(layer)
    if isinstance(spec, Path):
        built = _policy_file(spec, layer)
    elif callable(spec):
        built = Built(spec(), getattr(spec, "__name__", "agent"))
    else:
        built = _from_spec(spec, layer)
    if as_runtime and not isinstance(built.actor, Runtime):
        name = getattr(built.actor, "name", "")
        built = replace(built, actor=Runtime(built.actor, RuntimeConfig.off(), name=name))
    return _with_settings(built, settings) if settings else built


def _from_spec(spec: str, layer: str) -> Built:
    """`build` of a spec string, `layer` the mode where the spec has no prefix."""
    if spec.startswith("set:"):
        settings, _, inner = spec[len("set:") :].partition(":")
        return _with_settings(_from_spec(inner, layer), settings)
    mode = layer
    for prefix, prefixed in _MODES.items():
        if spec.startswith(prefix):
            if prefix in _RENAMED:
                renamed(f"the spec prefix {prefix!r}", repr(_RENAMED[prefix]), stacklevel=1)
            spec, mode = spec[len(prefix) :], prefixed
            break
    if spec.startswith(CONTROLLER):
        name = spec[len(CONTROLLER) :]
        try:
            controller = make_controller(name)
        except ValueError as exc:
            raise PolicyLoadError(str(exc)) from None
        if mode != "always":
            return Built(controller, f"controller {name}")
        behind = Runtime(controller, RuntimeConfig(), name=name)
        return Built(behind, f"controller {name} + layer")
    return _policy_file(Path(spec) if spec else shipped_policy(), mode)


def _policy_file(path: Path, layer: str) -> Built:
    """The policy file at `path` behind the runtime layer of `layer` (`load_policy`)."""
    return Built(load_policy(path, layer=layer), path.stem, path)


def _with_settings(built: Built, settings: str) -> Built:
    """`built` with the runtime settings K=V,K=V changed in its layer's config."""
    rt = built.actor
    if not isinstance(rt, Runtime):
        raise PolicyLoadError(
            f"runtime settings {settings!r}: {built.label} has no runtime layer to change "
            "(a policy file has; a controller has behind layer:controller:NAME)"
        )
    try:
        config = rt.config.with_settings(settings)
    except ValueError as exc:
        raise PolicyLoadError(str(exc)) from None
    changed = Runtime(rt.actor, config, rt.actions, rt.name, rt.metadata)
    joined = f"{built.settings},{settings}" if built.settings else settings
    return replace(built, actor=changed, label=f"{built.label} ({settings})", settings=joined)
