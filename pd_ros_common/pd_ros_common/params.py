"""Typed, checked node parameters: one check for start-up values and run-time `ros2 param set`.

A node lists its parameters as `name -> (default, description[, read_only])` (read_only defaults
to True) and, for values with a range, `name -> check(value) -> reason or None`. `declare`
declares them all with dynamic typing (so a wrong type is ours to report, in one line, instead of
rclpy's exception), checks every start-up value and registers the same check for later sets.
Integers are accepted for floating-point parameters (`rate_hz:=10`), and integer lists for float
lists, and are stored as what the parameter is: `-p rate_hz:=10` (or `ros2 param set ... 10`)
reads back as the double 10.0 on the parameter server, never as an integer. Any other type
mismatch is a `ParameterError` naming the parameter, the expected type and what was given.
"""

from __future__ import annotations

from array import array
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter

Check = Callable[[Any], "str | None"]
Spec = Sequence[Any]  # (default, description[, read_only])


class ParameterError(ValueError):
    """A parameter value of the wrong type or out of range (one line, names the parameter)."""


def _type_name(default: Any) -> str:
    if isinstance(default, bool):
        return "a bool"
    if isinstance(default, float):
        return "a double (an integer is fine too)"
    if isinstance(default, int):
        return "an integer"
    if isinstance(default, str):
        return "a string"
    return "a list of doubles"


def _number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def coerce(name: str, default: Any, value: Any) -> Any:
    """`value` as the type of `default` (int -> float allowed), else ParameterError."""
    if isinstance(default, bool):
        ok = isinstance(value, bool)
    elif isinstance(default, float):
        ok = _number(value)
    elif isinstance(default, int):
        ok = isinstance(value, int) and not isinstance(value, bool)
    elif isinstance(default, str):
        ok = isinstance(value, str)
    else:
        # a list from a launch file or -p; array.array from a SetParameters request
        ok = isinstance(value, (list, tuple, array)) and all(_number(v) for v in value)
    if not ok:
        raise ParameterError(
            f"parameter {name}: expected {_type_name(default)}, got {value!r} "
            f"({type(value).__name__})"
        )
    if isinstance(default, float):
        return float(value)
    if isinstance(default, (list, tuple)):
        return [float(v) for v in value]
    return value


def check_value(
    name: str, value: Any, parameters: Mapping[str, Spec], checks: Mapping[str, Check]
) -> Any:
    """The coerced value of parameter `name`, or ParameterError saying what is wrong."""
    v = coerce(name, parameters[name][0], value)
    why = checks[name](v) if name in checks else None
    if why:
        raise ParameterError(f"parameter {name}: {why} (got {v!r})")
    return v


def _stored_as_given(value: Any, coerced: Any) -> bool:
    """True if `value` is stored with the type of its coerced form (10 for 10.0 is not)."""
    if isinstance(coerced, list):
        return all(type(v) is float for v in value)
    return type(value) is type(coerced)


def _descriptor(spec: Spec) -> ParameterDescriptor:
    read_only = bool(spec[2]) if len(spec) > 2 else True
    return ParameterDescriptor(description=spec[1], read_only=read_only, dynamic_typing=True)


def declare(
    node: Node, parameters: Mapping[str, Spec], checks: Mapping[str, Check] | None = None
) -> dict[str, Any]:
    """Declare, check and return every parameter's value; later sets pass the same check.

    A value given as an integer for a double (`-p rate_hz:=10`) is declared again as the double
    (the override is then ignored: it is the value), so the parameter server holds 10.0; a later
    set of an integer is turned into the double before it is checked and stored."""
    checks = dict(checks or {})
    for name, spec in parameters.items():
        # Writable for now: a read-only parameter could not be declared again as its double.
        writable = ParameterDescriptor(description=spec[1], read_only=False, dynamic_typing=True)
        node.declare_parameter(name, spec[0], writable)
    values = {
        name: check_value(name, node.get_parameter(name).value, parameters, checks)
        for name in parameters
    }
    for name, spec in parameters.items():
        node.undeclare_parameter(name)
        node.declare_parameter(name, values[name], _descriptor(spec), ignore_override=True)

    def as_declared(params: list[Parameter]) -> list[Parameter]:
        """Integers for doubles become doubles (what is not a number is left to on_set)."""
        out = []
        for p in params:
            if p.name in parameters:
                try:
                    v = coerce(p.name, parameters[p.name][0], p.value)
                except ParameterError:
                    v = p.value
                if not _stored_as_given(p.value, v):
                    p = Parameter(p.name, value=v)
            out.append(p)
        return out

    def on_set(params: list[Parameter]) -> SetParametersResult:
        for p in params:
            if p.name in parameters:
                try:
                    check_value(p.name, p.value, parameters, checks)
                except ParameterError as exc:
                    return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    node.add_pre_set_parameters_callback(as_declared)
    node.add_on_set_parameters_callback(on_set)
    return values


def renamed(
    node: Node,
    values: Mapping[str, Any],
    parameters: Mapping[str, Spec],
    renames: Mapping[str, str],
) -> dict[str, Any]:
    """`values` with each deprecated parameter (`renames`: old name -> new, both declared) that
    is set to other than its default given to its new name, with one warning line each naming
    the new name; ParameterError in one line where the new one is set too, to another value."""
    used = {old: new for old, new in renames.items() if values[old] != parameters[old][0]}
    for old, new in used.items():
        if values[new] not in (parameters[new][0], values[old]):
            raise ParameterError(
                f"parameters {old} (deprecated) and {new} disagree: {values[old]!r} and "
                f"{values[new]!r}; set only {new}"
            )
    out = dict(values)
    for old, new in used.items():
        node.get_logger().warning(
            f"parameter {old} is deprecated, use {new}: {values[old]!r} is flown as {new}"
        )
        out[new] = values[old]
    return out


def value(node: Node, name: str, parameters: Mapping[str, Spec]) -> Any:
    """The current (already checked) value of a run-time parameter, coerced to its type."""
    return coerce(name, parameters[name][0], node.get_parameter(name).value)


def one_of(choices: Sequence[str]) -> Check:
    return lambda v: None if v in choices else f"must be one of {', '.join(choices)}"


def at_least(lo: float) -> Check:
    return lambda v: None if v >= lo else f"must be >= {lo:g}"


def above(lo: float) -> Check:
    return lambda v: None if v > lo else f"must be > {lo:g}"
