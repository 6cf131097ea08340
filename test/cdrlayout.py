"""Where the padding bytes of a message's CDR serialisation are, from its type definition.

``rclpy.serialization.serialize_message`` leaves alignment padding uninitialised (heap
garbage, e.g. ``00 32 2e 2b``), so its bytes can only be compared with another encoder's on
the non-padding positions. This walker finds those positions independently of
``ads_rca.contract.cdr``: it follows the rosidl ``SLOT_TYPES`` of the message object (XCDR1,
alignment = primitive size relative to the payload start, after the 4-byte header).
"""

from __future__ import annotations

from typing import Any

from rosidl_parser import definition as d

_SIZES = {
    "boolean": 1,
    "octet": 1,
    "char": 1,
    "uint8": 1,
    "int8": 1,
    "int16": 2,
    "uint16": 2,
    "int32": 4,
    "uint32": 4,
    "float": 4,
    "int64": 8,
    "uint64": 8,
    "double": 8,
}


class _Layout:
    def __init__(self) -> None:
        self.position = 0
        self.padding: list[int] = []

    def align(self, size: int) -> None:
        while self.position % size:
            self.padding.append(self.position)
            self.position += 1

    def primitive(self, size: int, count: int = 1) -> None:
        if count:
            self.align(size)
            self.position += size * count

    def value(self, value: Any, slot: Any) -> None:
        if isinstance(slot, d.BasicType):
            self.primitive(_SIZES[slot.typename])
        elif isinstance(slot, d.AbstractString):
            self.primitive(4)
            self.position += len(value.encode()) + 1
        elif isinstance(slot, d.NamespacedType):
            for name, field in zip(value.__slots__, type(value).SLOT_TYPES, strict=False):
                self.value(getattr(value, name), field)
        elif isinstance(slot, d.AbstractSequence | d.Array):
            if isinstance(slot, d.AbstractSequence):
                self.primitive(4)
            inner = slot.value_type
            if isinstance(inner, d.BasicType):
                self.primitive(_SIZES[inner.typename], len(value))
            else:
                for item in value:
                    self.value(item, inner)
        else:  # pragma: no cover - not used by the contract
            raise TypeError(f"unsupported slot type {slot!r}")


def padding_positions(msg: Any) -> list[int]:
    """Offsets (in the serialised bytes, header included) of every alignment padding byte."""
    layout = _Layout()
    for name, field in zip(msg.__slots__, type(msg).SLOT_TYPES, strict=False):
        layout.value(getattr(msg, name), field)
    return [4 + p for p in layout.padding]


def serialised_size(msg: Any) -> int:
    """Length of the CDR bytes the layout implies (header included, no trailing padding)."""
    layout = _Layout()
    for name, field in zip(msg.__slots__, type(msg).SLOT_TYPES, strict=False):
        layout.value(getattr(msg, name), field)
    return 4 + layout.position


def differences(ours: bytes, reference: bytes, msg: Any) -> list[str]:
    """Why ``ours`` is not ``reference`` (rclpy's bytes for ``msg``) on non-padding bytes,
    or why our padding is not zero; empty when they agree."""
    problems: list[str] = []
    if type(msg).__name__ == "JointState" and len(reference) == serialised_size(msg) + 8:
        # rclpy's size calculation aligns the two empty float64[] (velocity, effort) that
        # its writer does not: 8 uninitialised bytes at the end that no reader looks at
        # (test_ros_tool_conventions.py::test_joint_state_bytes_equal_rclpy).
        reference = reference[:-8]
    if len(ours) != len(reference):
        problems.append(f"length {len(ours)} != {len(reference)}")
    if serialised_size(msg) != len(reference):
        problems.append(f"layout walker size {serialised_size(msg)} != {len(reference)}")
    padding = set(padding_positions(msg))
    for i, (a, b) in enumerate(zip(ours, reference, strict=False)):
        if i in padding:
            if a != 0:
                problems.append(f"padding byte {i} is {a:#x}, not 0")
        elif a != b:
            problems.append(f"byte {i}: {a:#x} != {b:#x}")
        if len(problems) > 10:
            break
    return problems
