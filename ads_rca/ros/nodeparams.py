"""ROS parameters shared by the live graph's nodes: the engine's, and the node's own.

The engine's parameters keep their ``params.py`` names (so ``--params-file
config/rca_*.yaml`` and ``-p effect_time_window:=15`` work as for ``ads-rca diagnose``):
``semantics`` is declared first, then every threshold with that mode's default, dynamically
typed (a YAML ``1`` for a float threshold is fine) and validated by ``make_params``.
"""

from __future__ import annotations

from dataclasses import asdict, fields
from typing import Any

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node

from ads_rca.errors import InputError
from ads_rca.params import DEFAULT_SEMANTICS, SEMANTICS, Params, make_params

ENGINE_NAMES: tuple[str, ...] = tuple(f.name for f in fields(Params) if f.name != "semantics")


def declare_engine_parameters(node: Node) -> Params:
    """Declare ``semantics`` and every threshold; the resulting :class:`Params`.

    Raises InputError for an unknown mode or a value that is not a number.
    """
    node.declare_parameter(
        "semantics",
        DEFAULT_SEMANTICS,
        ParameterDescriptor(description=f"Oracle semantics: {' or '.join(SEMANTICS)}."),
    )
    semantics = str(node.get_parameter("semantics").value)
    if semantics not in SEMANTICS:
        raise InputError(f"semantics must be one of {', '.join(SEMANTICS)}, not {semantics!r}")
    defaults = asdict(make_params(semantics))
    values: dict[str, Any] = {}
    for name in ENGINE_NAMES:
        descriptor = ParameterDescriptor(
            description="Engine threshold (see ads_rca/params.py).", dynamic_typing=True
        )
        node.declare_parameter(name, defaults[name], descriptor)
        values[name] = node.get_parameter(name).value
    return make_params(semantics, values)


def declare_node_parameters(node: Node, table: dict[str, tuple[Any, str]]) -> dict[str, Any]:
    """Declare the node's own parameters (name → (default, description)); their values.

    Doubles are dynamically typed so that ``-p timeout:=5`` (an integer) is accepted.
    """
    out: dict[str, Any] = {}
    for name, (default, description) in table.items():
        descriptor = ParameterDescriptor(
            description=description, dynamic_typing=isinstance(default, float)
        )
        node.declare_parameter(name, default, descriptor)
        value = node.get_parameter(name).value
        out[name] = float(value) if isinstance(default, float) else value
    return out


def engine_values(params: Params) -> dict[str, bool | int | float | str]:
    """Every engine parameter as ``-p`` values for a node (semantics included)."""
    return dict(asdict(params).items())
