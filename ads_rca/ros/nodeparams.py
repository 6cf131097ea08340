"""ROS parameters shared by the live graph's nodes: the engine's, and the node's own.

The engine's parameters keep their ``params.py`` names (so ``--params-file
config/rca_*.yaml`` and ``-p safety_margin:=0.8`` work as for ``ads-rca diagnose``):
``semantics`` is declared first, then every threshold with that mode's default, dynamically
typed (a YAML ``1`` for a float threshold is fine) and validated by ``make_params``.

Every value is checked by our code, in the CLI's words (a wrong type, no number, out of
range: one line naming the parameter and its range, exit 2); then each parameter's
descriptor is made read-only, carrying its range (``FloatingPointRange`` /
``IntegerRange``) and what it does in the node's mode, for ``ros2 param describe``. Why
read-only: a node reads its parameters once, at start (a monitor's window and the
aggregator's verdict are built from them), so a runtime ``ros2 param set`` is refused
rather than reported as a success that changes nothing. A ``-p name:=value`` (or params
file entry) for a parameter the node does not have is refused with the known names.

A value given on the command line wins over every params file, as ROS users expect: rcl
merges the files' and ``-p``'s values by node-name pattern, so a file's node-specific
section (``/**/aggregator``) was applied after a ``-p`` (a ``/**`` rule) and silently beat
it. Each node passes :func:`command_line_overrides` as its ``parameter_overrides``, which
rclpy applies last.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import asdict, fields
from typing import Any

import yaml
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
)
from rclpy.exceptions import ParameterException, ParameterUninitializedException
from rclpy.node import Node
from rclpy.parameter import Parameter

from ads_rca.errors import ConfigError
from ads_rca.foundation.text import printable
from ads_rca.oracles.semantics import semantics_for
from ads_rca.params import DEFAULT_SEMANTICS, SEMANTICS, Params, make_params
from ads_rca.paramspec import SPECS, Choice, Range, check_number

ENGINE_NAMES: tuple[str, ...] = tuple(f.name for f in fields(Params) if f.name != "semantics")
#: Parameters rclpy declares on every node itself.
ROS_NODE_PARAMETERS: tuple[str, ...] = ("use_sim_time", "start_type_description_service")

#: A node's own parameter: (default, description), plus its range when it is a number.
NodeParameter = tuple[Any, str] | tuple[Any, str, Range]


def command_line_rules(node_name: str, argv: Sequence[str]) -> dict[str, str]:
    """``-p``/``--param`` assignments in ``argv``'s ``--ros-args`` sections that apply to
    ``node_name`` (``name:=value``, or ``node:name:=value`` for this node), name → value
    text, the last one of a name winning (as in rcl)."""
    rules: dict[str, str] = {}
    inside = False
    tokens = iter(argv)
    for token in tokens:
        if token == "--ros-args":
            inside = True
        elif token == "--":
            inside = False
        elif inside and token in ("-p", "--param"):
            rule = next(tokens, "")
            target, sep, text = rule.partition(":=")
            if not sep:
                continue  # rcl refuses it on its own
            node, colon, name = target.rpartition(":")
            if not colon or node.strip("/") in (node_name, "*", "**"):
                rules[name] = text
    return rules


def command_line_overrides(
    node_name: str, argv: Sequence[str] | None = None
) -> list[Parameter[Any]]:
    """The command line's values for ``node_name`` (:func:`command_line_rules` of
    ``sys.argv``), typed as rcl types them (a YAML scalar or list), for the node's
    ``parameter_overrides``. ConfigError (one line) for a value rcl could not have read."""
    out: list[Parameter[Any]] = []
    for name, text in command_line_rules(node_name, sys.argv if argv is None else argv).items():
        try:
            value = yaml.safe_load(text) if text.strip() else text
        except yaml.YAMLError:
            value = text
        scalar = (bool, int, float, str)
        listed = isinstance(value, list) and all(isinstance(v, scalar) for v in value)
        if not (isinstance(value, scalar) or listed):
            value = text  # rcl keeps what is no scalar or flat list as the text given
        try:
            out.append(Parameter(name, value=value))
        except (TypeError, ValueError):
            raise ConfigError(
                printable(f"parameter {name}: {text[:80]!r} mixes types in one array")
            ) from None
    return out


def declare_engine_parameters(node: Node) -> Params:
    """Declare ``semantics`` and every threshold; the resulting :class:`Params`.

    Raises ConfigError for an unknown mode, a value that is not a number or out of range.
    """
    modes = " or ".join(SEMANTICS)
    semantics_text = f"Oracle semantics: {modes}; read once at start."
    semantics = str(_declare(node, "semantics", DEFAULT_SEMANTICS, _descriptor(semantics_text)))
    if semantics not in SEMANTICS:
        raise ConfigError(f"semantics must be one of {', '.join(SEMANTICS)}, not {semantics!r}")
    _freeze(node, "semantics", _descriptor(semantics_text, constraints=f"one of {modes}"))
    defaults = asdict(make_params(semantics))
    values: dict[str, Any] = {}
    texts: dict[str, str] = {}
    for name in ENGINE_NAMES:
        texts[name] = f"In {semantics} mode: {SPECS[name].effect_in(semantics)}."
        values[name] = _declare(node, name, defaults[name], _descriptor(texts[name], True))
    params = make_params(semantics, values)
    for name in ENGINE_NAMES:
        bounds = SPECS[name].range
        if isinstance(bounds, Choice):
            _freeze(node, name, _descriptor(texts[name], True, constraints=bounds.text()))
        else:
            _freeze(node, name, _descriptor(texts[name], True, bounds))
    return params


def declare_node_parameters(
    node: Node, table: dict[str, NodeParameter], engine: Params | None = None
) -> dict[str, Any]:
    """Declare the node's own parameters (name → (default, description[, range])); their
    values. Call it last: it refuses overrides of parameters the node did not declare
    (``engine``: the node declared the engine parameters first). Once the node has started,
    it says so with :func:`log_in_force`.

    Doubles are dynamically typed so that ``-p timeout:=5`` (an integer) is accepted; a list
    default is a string array. A value of the wrong type (``-p start_frame:=abc``), a double
    that is no number, or a number out of its range raises ConfigError naming the parameter
    (one line, exit 2), never rclpy's traceback.
    """
    out: dict[str, Any] = {}
    for name, entry in table.items():
        default, description = entry[0], entry[1]
        bounds = entry[2] if len(entry) > 2 else None
        is_float = isinstance(default, float)
        numeric = is_float or (isinstance(default, int) and not isinstance(default, bool))
        if numeric and bounds is None:
            raise TypeError(f"parameter {name}: a number needs a range in the node's table")
        first = _descriptor(description, is_float, array=isinstance(default, list))
        value = _declare(node, name, default, first)
        out[name] = check_number(name, value, bounds) if bounds is not None else value
        _freeze(node, name, _descriptor(description, is_float, bounds))
    refuse_unknown(node, [*(("semantics", *ENGINE_NAMES) if engine else ()), *table])
    return out


def refuse_unknown(node: Node, known: list[str]) -> None:
    """ConfigError when the command line or a params file set a parameter this node does not
    have (a misspelt name would otherwise be silently ignored).

    rclpy keeps the overrides meant for this node in ``Node._parameter_overrides`` (the same
    attribute from Humble to Kilted) and has no public accessor for them.
    """
    overrides: dict[str, Any] = getattr(node, "_parameter_overrides", {})
    unknown = sorted(name for name in overrides if not node.has_parameter(name))
    if unknown:
        names = ", ".join(sorted({*known, *ROS_NODE_PARAMETERS}))
        raise ConfigError(
            printable(f"unknown parameter {', '.join(map(repr, unknown))} (known: {names})")
        )


def log_in_force(node: Node, values: dict[str, Any], engine: Params | None = None) -> None:
    """Log the one line of :func:`in_force`: at the end of a node's start, so a node that
    refuses to start never claims values were in force."""
    node.get_logger().info(in_force(engine, values))


def in_force(engine: Params | None, values: dict[str, Any]) -> str:
    """One line: the mode and the thresholds it reads (engine nodes), then the node's own
    settings, as the node will use them."""
    settings = ", ".join(f"{name}={value!r}" for name, value in values.items())
    if engine is None:
        return printable(f"parameters in force: {settings}")
    semantics = semantics_for(engine)
    thresholds = ", ".join(f"{k}={v!r}" for k, v in semantics.used(engine).items())
    return printable(
        f"parameters in force: semantics {engine.semantics}; thresholds: {thresholds}; "
        f"node: {settings}"
    )


def _descriptor(
    description: str,
    dynamic: bool = False,
    bounds: Range | None = None,
    constraints: str = "",
    array: bool = False,
) -> ParameterDescriptor:
    """A fresh descriptor (rclpy stores the one it is given: never reuse one)."""
    descriptor = ParameterDescriptor(description=description, dynamic_typing=dynamic)
    if array:
        descriptor.type = ParameterType.PARAMETER_STRING_ARRAY
    if bounds is not None:
        descriptor.additional_constraints = constraints or f"range {bounds.text()}"
        if bounds.integer:
            descriptor.integer_range = [
                IntegerRange(from_value=int(bounds.low), to_value=int(bounds.high), step=1)
            ]
        else:
            descriptor.floating_point_range = [
                FloatingPointRange(from_value=bounds.low, to_value=bounds.high, step=0.0)
            ]
    elif constraints:
        descriptor.additional_constraints = constraints
    return descriptor


def _declare(node: Node, name: str, default: Any, descriptor: ParameterDescriptor) -> Any:
    """Declare ``name``; its value. An empty list default is declared by type (rclpy would
    take ``[]`` for a byte array and refuse every list of strings given for it)."""
    empty_list = isinstance(default, list) and not default
    try:
        node.declare_parameter(
            name, Parameter.Type.STRING_ARRAY if empty_list else default, descriptor
        )
        value = node.get_parameter(name).value
    except ParameterUninitializedException:  # no value given: the empty list, typed
        node.set_parameters([Parameter(name, Parameter.Type.STRING_ARRAY, [])])
        return []
    except ParameterException as error:
        raise ConfigError(printable(f"parameter {name}: {error}")) from None
    return value


def _freeze(node: Node, name: str, descriptor: ParameterDescriptor) -> None:
    """The final descriptor: read-only, with the range (the value was checked already)."""
    descriptor.read_only = True
    descriptor.type = node.describe_parameter(name).type  # a dynamic one follows the value
    node.set_descriptor(name, descriptor)
