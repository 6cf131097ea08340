"""ROS message objects ↔ CDR bytes without rclpy, through rosbags' Kilted type store.

Bags hold CDR bytes; the converter and the assembler work on the message packages' Python
classes (``std_msgs.msg.String`` ...). rclpy can serialise those, but bag conversion must
not need a ROS runtime, so this module walks a message by its rosbags field definitions and
builds the rosbags twin (and back). ``Stores.ROS2_KILTED`` matches rclpy exactly: the same
RIHS01 type hashes, the same CDR bytes (tested against ``rclpy.serialization``). It also
gives the concatenated ``ros2msg`` definition text a rosbag2 schema carries. Types the store
does not know are loaded from the ``.msg`` files of the installed packages (``share/``).
"""

from __future__ import annotations

import importlib
import os
import sys
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from ads_rca.contract.errors import UnknownMessageType

#: rosbags base type → numpy dtype of its arrays and sequences.
_DTYPES: dict[str, str] = {
    "bool": "bool",
    "byte": "uint8",
    "char": "uint8",
    "octet": "uint8",
    "int8": "int8",
    "uint8": "uint8",
    "int16": "int16",
    "uint16": "uint16",
    "int32": "int32",
    "uint32": "uint32",
    "int64": "int64",
    "uint64": "uint64",
    "float32": "float32",
    "float64": "float64",
}


@cache
def typestore() -> Typestore:
    """The process-wide Kilted type store (types from ``share/`` are added on demand)."""
    return get_typestore(Stores.ROS2_KILTED)


def type_name(message_class: type[Any]) -> str:
    """``visualization_msgs.msg.MarkerArray`` → ``visualization_msgs/msg/MarkerArray``."""
    package = message_class.__module__.split(".")[0]
    return f"{package}/msg/{message_class.__name__}"


def normalise_type(name: str) -> str:
    """``pkg/Type`` or ``pkg/msg/Type`` → ``pkg/msg/Type``."""
    parts = name.strip("/").split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    return "/".join(parts)


@cache
def message_class(name: str) -> type[Any]:
    """The message package's Python class of ``pkg/msg/Type`` (imports the package)."""
    package, _, short = normalise_type(name).split("/")
    found: type[Any] = getattr(importlib.import_module(f"{package}.msg"), short)
    return found


def _share_dirs() -> list[Path]:
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    prefixes.append(sys.prefix)
    return [Path(p) / "share" for p in prefixes]


def ensure_type(name: str) -> str:
    """Make sure the store knows ``name`` and its dependencies; return the normalised name.

    Raises UnknownMessageType (a KeyError) when no installed package has a ``.msg`` file
    for it.
    """
    name = normalise_type(name)
    store = typestore()
    pending = [name]
    while pending:
        current = pending.pop()
        if current in store.fielddefs:
            continue
        package, _, short = current.split("/")
        for share in _share_dirs():
            path = share / package / "msg" / f"{short}.msg"
            if path.is_file():
                types = get_types_from_msg(path.read_text(encoding="utf-8"), current)
                store.register(types)
                for _consts, fields in types.values():
                    pending.extend(referenced_types(fields))
                break
        else:
            raise UnknownMessageType(f"unknown message type {current!r} (no .msg file installed)")
    return name


def referenced_types(fields: Any) -> list[str]:
    """The message types a type's field definitions name (rosbags ``fielddefs[name][1]``)."""
    out: list[str] = []
    for _name, (nodetype, spec) in fields:
        if nodetype == Nodetype.NAME:
            out.append(spec)
        elif nodetype in (Nodetype.ARRAY, Nodetype.SEQUENCE) and spec[0][0] == Nodetype.NAME:
            out.append(spec[0][1])
    return out


def message_definition(name: str) -> str:
    """The concatenated ``ros2msg`` text of a type (its fields, then every dependency)."""
    text, _ = typestore().generate_msgdef(ensure_type(name), ros_version=2)
    return text


def type_hash(name: str) -> str:
    """RIHS01 type description hash, as rclpy and rosbag2 report it."""
    return typestore().hash_rihs01(ensure_type(name))


# --- message packages → rosbags ------------------------------------------------------------


def to_store(msg: Any, name: str | None = None) -> Any:
    """A message package object → the rosbags dataclass of the same type."""
    name = ensure_type(name or type_name(type(msg)))
    store = typestore()
    _consts, fields = store.fielddefs[name]
    values = {field: _to_store_value(getattr(msg, field), node) for field, node in fields}
    return store.types[name](**values)


def _to_store_value(value: Any, node: Any) -> Any:
    nodetype, spec = node
    if nodetype == Nodetype.BASE:
        if isinstance(value, bytes):  # rosidl byte: a one-byte bytes object
            return value[0]
        return value
    if nodetype == Nodetype.NAME:
        return to_store(value, spec)
    (subtype, subspec), _length = spec
    if subtype == Nodetype.NAME:
        return [to_store(item, subspec) for item in value]
    base = subspec[0]
    if base == "string":
        return list(value)
    return np.asarray(bytearray(value) if isinstance(value, bytes) else value, dtype=_DTYPES[base])


def serialize(msg: Any, name: str | None = None) -> bytes:
    """CDR bytes of a message package object (byte-identical to rclpy's)."""
    name = ensure_type(name or type_name(type(msg)))
    return bytes(typestore().serialize_cdr(to_store(msg, name), name))


# --- rosbags → message packages ------------------------------------------------------------


def from_store(obj: Any, name: str) -> Any:
    """A rosbags dataclass → the message package's object of the same type."""
    name = normalise_type(name)
    _consts, fields = typestore().fielddefs[name]
    cls = message_class(name)
    values = {field: _from_store_value(getattr(obj, field), node) for field, node in fields}
    return cls(**values)


def _from_store_value(value: Any, node: Any) -> Any:
    nodetype, spec = node
    if nodetype == Nodetype.BASE:
        if spec[0] == "byte":
            return bytes([int(value)])
        return value.item() if isinstance(value, np.generic) else value
    if nodetype == Nodetype.NAME:
        return from_store(value, spec)
    (subtype, subspec), _length = spec
    if subtype == Nodetype.NAME:
        return [from_store(item, subspec) for item in value]
    if subspec[0] == "byte":
        return [bytes([int(v)]) for v in value]
    return value.tolist() if isinstance(value, np.ndarray) else list(value)


def deserialize(data: bytes | memoryview, name: str) -> Any:
    """CDR bytes → the message package's object (no rclpy)."""
    name = ensure_type(name)
    return from_store(typestore().deserialize_cdr(data, name), name)
