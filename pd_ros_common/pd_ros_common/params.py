"""Typed, checked node parameters: one check for start-up values and run-time `ros2 param set`.

A node lists its parameters as `name -> (default, description[, read_only])` (read_only defaults
to True) and, for values with a range, `name -> check(value) -> reason or None`. `declare`
declares them all with dynamic typing (so a wrong type is ours to report, in one line, instead of
rclpy's exception), checks every start-up value and registers the same check for later sets.
Integers are accepted for floating-point parameters (`rate_hz:=10`), and integer lists for float
lists; any other type mismatch is a `ParameterError` naming the parameter, the expected type and
what was given.
"""

from __future__ import annotations

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
        ok = isinstance(value, (list, tuple)) and all(_number(v) for v in value)
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


def declare(
    node: Node, parameters: Mapping[str, Spec], checks: Mapping[str, Check] | None = None
) -> dict[str, Any]:
    """Declare, check and return every parameter's value; later sets pass the same check."""
    checks = dict(checks or {})
    for name, spec in parameters.items():
        read_only = bool(spec[2]) if len(spec) > 2 else True
        node.declare_parameter(
            name,
            spec[0],
            ParameterDescriptor(description=spec[1], read_only=read_only, dynamic_typing=True),
        )
    values = {
        name: check_value(name, node.get_parameter(name).value, parameters, checks)
        for name in parameters
    }

    def on_set(params: list[Parameter]) -> SetParametersResult:
        for p in params:
            if p.name in parameters:
                try:
                    check_value(p.name, p.value, parameters, checks)
                except ParameterError as exc:
                    return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(on_set)
    return values


def value(node: Node, name: str, parameters: Mapping[str, Spec]) -> Any:
    """The current (already checked) value of a run-time parameter, coerced to its type."""
    return coerce(name, parameters[name][0], node.get_parameter(name).value)


def one_of(choices: Sequence[str]) -> Check:
    return lambda v: None if v in choices else f"must be one of {', '.join(choices)}"


def at_least(lo: float) -> Check:
    return lambda v: None if v >= lo else f"must be >= {lo:g}"


def above(lo: float) -> Check:
    return lambda v: None if v > lo else f"must be > {lo:g}"
