"""Real stacks' messages and bags for the profile tests, built with rosbags from the
published ``.msg`` definitions shipped in ``ads_rca/synth/msgs`` (the layouts a recording of
Autoware, the CARLA ROS bridge or vision_msgs carries).

``build(store, type, values)`` makes a message object from a nested dict, every field not
given at its zero value, so a test states only what it checks. ``write_bag`` writes real
rosbag2 bags (MCAP or sqlite3) with rosbags' own writer.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.interfaces import Nodetype
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from ads_rca.contract.errors import MalformedMessage
from ads_rca.sources.bag.storage import BagMessage

MSGS = Path(__file__).resolve().parents[1] / "ads_rca" / "synth" / "msgs"
_NUMPY = {
    "bool": np.bool_,
    "int8": np.int8,
    "uint8": np.uint8,
    "byte": np.uint8,
    "char": np.uint8,
    "int16": np.int16,
    "uint16": np.uint16,
    "int32": np.int32,
    "uint32": np.uint32,
    "int64": np.int64,
    "uint64": np.uint64,
    "float32": np.float32,
    "float64": np.float64,
}


def definitions(overrides: Mapping[str, str] | None = None) -> dict[str, str]:
    """Type name → .msg text of every shipped definition (``overrides`` replace some)."""
    out = {
        f"{path.parents[1].name}/msg/{path.stem}": path.read_text(encoding="utf-8")
        for path in sorted(MSGS.glob("*/msg/*.msg"))
    }
    out.update(overrides or {})
    return out


def typestore(overrides: Mapping[str, str] | None = None) -> Typestore:
    """Kilted's standard types plus the real stacks' (``overrides``: type → .msg text, for
    hostile layouts; a standard type overridden is dropped from the base first)."""
    base = get_typestore(Stores.ROS2_KILTED)
    store = get_typestore(Stores.EMPTY)
    kept = {name: d for name, d in base.fielddefs.items() if name not in (overrides or {})}
    store.register(kept)
    for name, text in definitions(overrides).items():
        store.register(get_types_from_msg(text, name))
    return store


def build(store: Typestore, type_name: str, values: Mapping[str, Any] | None = None) -> Any:
    """A message object of ``type_name``: ``values`` (nested dicts; lists of dicts for
    sequences of messages) over zero defaults."""
    values = dict(values or {})
    _consts, fields = store.fielddefs[type_name]
    kwargs: dict[str, Any] = {}
    for name, (kind, detail) in fields:
        given = values.pop(name, None)
        kwargs[name] = _value(store, kind, detail, given)
    if values:
        raise KeyError(f"{type_name} has no fields {sorted(values)}")
    return store.types[type_name](**kwargs)


def _value(store: Typestore, kind: int, detail: Any, given: Any) -> Any:
    if kind == Nodetype.NAME:
        return (
            given
            if given is not None and not isinstance(given, dict)
            else build(store, detail, given)
        )
    if kind == Nodetype.BASE:
        if given is not None:
            return given
        base = detail[0]
        return (
            "" if base == "string" else False if base == "bool" else 0.0 if "float" in base else 0
        )
    (sub_kind, sub_detail), count = detail
    if sub_kind == Nodetype.BASE and sub_detail[0] != "string":
        dtype = _NUMPY[sub_detail[0]]
        if given is not None:
            return np.asarray(given, dtype=dtype)
        return np.zeros(count if kind == Nodetype.ARRAY else 0, dtype=dtype)
    items = list(given or [])
    if kind == Nodetype.ARRAY:
        items += [None] * (count - len(items))
    return [_value(store, sub_kind, sub_detail, item) for item in items]


def stamp(ns: int) -> dict[str, int]:
    """A builtin_interfaces/Time value."""
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


def header(ns: int, frame_id: str = "map") -> dict[str, Any]:
    return {"stamp": stamp(ns), "frame_id": frame_id}


def write_bag(
    path: Path,
    store: Typestore,
    messages: Iterable[tuple[str, str, int, Any]],
    storage: str = "mcap",
) -> Path:
    """A rosbag2 bag of (topic, type, log time ns, message object) at ``path``."""
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=9, storage_plugin=plugin) as writer:
        connections: dict[str, Any] = {}
        for topic, type_name, log_time, msg in messages:
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, type_name, typestore=store)
            writer.write(connections[topic], log_time, store.serialize_cdr(msg, type_name))
    return path


def decoder(store: Typestore) -> Callable[[BagMessage, str], Any]:
    """``decode(message, type)`` as the reader wants it: rosbags' deserialisation, its
    failures as MalformedMessage (what the bag's own types will give)."""

    def decode(message: BagMessage, type_name: str) -> Any:
        try:
            return store.deserialize_cdr(message.data, type_name)
        except Exception as error:  # rosbags reports bad bytes with several error types
            raise MalformedMessage(f"cannot deserialise: {error}") from error

    return decode
