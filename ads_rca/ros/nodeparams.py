"""ROS parameters shared by the live graph's nodes: the engine's, and the node's own.

The engine's parameters keep their ``params.py`` names (so ``--params-file
config/rca_*.yaml`` and ``-p effect_time_window:=15`` work as for ``ads-rca diagnose``):
``semantics`` is declared first, then every threshold with that mode's default, dynamically
typed (a YAML ``1`` for a float threshold is fine) and validated by ``make_params``.
"""

from __future__ import annotations

from dataclasses import asdict, fields
from typing import Any

from rcl_interfaces.msg import ParameterDescriptor, ParameterType
from rclpy.exceptions import ParameterException
from rclpy.node import Node

from ads_rca.errors import ConfigError
from ads_rca.params import DEFAULT_SEMANTICS, SEMANTICS, Params, make_params
from ads_rca.text import printable

ENGINE_NAMES: tuple[str, ...] = tuple(f.name for f in fields(Params) if f.name != "semantics")


def declare_engine_parameters(node: Node) -> Params:
    """Declare ``semantics`` and every threshold; the resulting :class:`Params`.

    Raises ConfigError for an unknown mode or a value that is not a number.
    """
    semantics = str(
        _declare(
            node,
            "semantics",
            DEFAULT_SEMANTICS,
            ParameterDescriptor(description=f"Oracle semantics: {' or '.join(SEMANTICS)}."),
        )
    )
    if semantics not in SEMANTICS:
        raise ConfigError(f"semantics must be one of {', '.join(SEMANTICS)}, not {semantics!r}")
    defaults = asdict(make_params(semantics))
    values: dict[str, Any] = {}
    for name in ENGINE_NAMES:
        descriptor = ParameterDescriptor(
            description="Engine threshold (see ads_rca/params.py).", dynamic_typing=True
        )
        values[name] = _declare(node, name, defaults[name], descriptor)
    return make_params(semantics, values)


def declare_node_parameters(node: Node, table: dict[str, tuple[Any, str]]) -> dict[str, Any]:
    """Declare the node's own parameters (name → (default, description)); their values.

    Doubles are dynamically typed so that ``-p timeout:=5`` (an integer) is accepted; a list
    default is a string array. A value of the wrong type (``-p start_frame:=abc``) or a
    double that is no number raises ConfigError naming the parameter (one line, exit 2),
    never rclpy's traceback.
    """
    out: dict[str, Any] = {}
    for name, (default, description) in table.items():
        descriptor = ParameterDescriptor(
            description=description, dynamic_typing=isinstance(default, float)
        )
        if isinstance(default, list):
            descriptor.type = ParameterType.PARAMETER_STRING_ARRAY
        value = _declare(node, name, default, descriptor)
        out[name] = _number(name, value) if isinstance(default, float) else value
    return out


def _declare(node: Node, name: str, default: Any, descriptor: ParameterDescriptor) -> Any:
    try:
        node.declare_parameter(name, default, descriptor)
    except ParameterException as error:
        raise ConfigError(printable(f"parameter {name}: {error}")) from None
    return node.get_parameter(name).value


def _number(name: str, value: Any) -> float:
    if isinstance(value, bool):
        raise ConfigError(f"parameter {name}: {value!r} is not a number")
    try:
        return float(value)
    except (TypeError, ValueError):
        raise ConfigError(printable(f"parameter {name}: {value!r} is not a number")) from None
