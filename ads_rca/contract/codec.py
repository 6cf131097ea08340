"""How each kind of record travels: its message type and its conversions on both paths.

One :class:`Codec` per kind (ego pose, actors, boxes, predictions, plan, 3-D objects, control
command, lane graph, JSON text, clock) holds the four conversions a topic needs, so the topic
table (:mod:`ads_rca.contract.topics`) gives a topic its kind in one row and everything else
follows from it:

- ``build`` / ``read``: record ↔ rclpy message object (:mod:`~ads_rca.contract.convert`:
  what publishing objects, bags and the tests use);
- ``encode`` / ``decode``: record ↔ the same message's CDR bytes without objects
  (:mod:`~ads_rca.contract.cdr`, :mod:`~ads_rca.contract.cdr_decode`: the measured fast
  path, byte-equal to rclpy's serialisation of ``build``; ``test/test_ros_cdr.py``);
- ``stamp``: the log time a message's bytes carry, read without decoding the rest.

Changing a field of a kind means changing its four functions together, which the tests hold
to each other; adding a topic of an existing kind is one row of the table. Two topics of one
MarkerArray kind differ only in their :class:`~ads_rca.contract.convert.MarkerStyle`, which
is why those kinds are made per style. ``frame_ms`` (the run's milliseconds per frame) is passed
to every conversion because a plan's step keys are times. Pure: no rclpy import.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

from ads_rca.contract import cdr, cdr_decode, convert
from ads_rca.contract.convert import MarkerStyle
from ads_rca.model import Actors, Boxes, ControlCommand, EgoPose, Objects3D, Plan, Predictions
from ads_rca.sources.openlane.lanes import LaneGraph

R = TypeVar("R")


@dataclass(frozen=True, slots=True)
class Codec(Generic[R]):
    """One kind of record on the wire: message type name and the conversions (module doc)."""

    type_name: str  # ``package/msg/Type``
    build: Callable[[R, int, int], Any]  # (record, stamp_ms, frame_ms) -> message object
    read: Callable[[Any, int], R]  # (message object, frame_ms) -> record
    encode: Callable[[R, int, int], bytes]  # (record, stamp_ms, frame_ms) -> CDR bytes
    decode: Callable[[bytes, int], R]  # (CDR bytes, frame_ms) -> record; CdrError if malformed
    stamp: Callable[[bytes], int] | None = None  # CDR bytes -> stamp_ms (data kinds)


POSE: Codec[EgoPose] = Codec(
    "nav_msgs/msg/Odometry",
    build=lambda pose, stamp, _frame_ms: convert.pose_to_odometry(pose, stamp),
    read=lambda msg, _frame_ms: convert.odometry_to_pose(msg),
    encode=lambda pose, stamp, _frame_ms: cdr.encode_odometry(pose, stamp),
    decode=lambda data, _frame_ms: cdr_decode.decode_odometry(data),
    stamp=cdr_decode.header_stamp_ms,
)

PLAN: Codec[Plan] = Codec(
    "trajectory_msgs/msg/MultiDOFJointTrajectory",
    build=convert.plan_to_trajectory,
    read=convert.trajectory_to_plan,
    encode=cdr.encode_trajectory,
    decode=cdr_decode.decode_trajectory,
    stamp=cdr_decode.header_stamp_ms,
)

_MARKER_ARRAY = "visualization_msgs/msg/MarkerArray"


def actors(style: MarkerStyle) -> Codec[Actors]:
    """Actors as CUBE markers in ``style``."""
    return Codec(
        _MARKER_ARRAY,
        build=lambda record, stamp, _frame_ms: convert.actors_to_markers(record, stamp, style),
        read=lambda msg, _frame_ms: convert.markers_to_actors(msg),
        encode=lambda record, stamp, _frame_ms: cdr.encode_actors(record, stamp, style),
        decode=lambda data, _frame_ms: cdr_decode.decode_actors(data),
        stamp=cdr_decode.marker_array_stamp_ms,
    )


def boxes(style: MarkerStyle) -> Codec[Boxes]:
    """Image boxes as LINE_STRIP markers in ``style``."""
    return Codec(
        _MARKER_ARRAY,
        build=lambda record, stamp, _frame_ms: convert.boxes_to_markers(record, stamp, style),
        read=lambda msg, _frame_ms: convert.markers_to_boxes(msg),
        encode=lambda record, stamp, _frame_ms: cdr.encode_boxes(record, stamp, style),
        decode=lambda data, _frame_ms: cdr_decode.decode_boxes(data),
        stamp=cdr_decode.marker_array_stamp_ms,
    )


def predictions(style: MarkerStyle) -> Codec[Predictions]:
    """Predicted tracks as LINE_STRIP markers in ``style``."""
    return Codec(
        _MARKER_ARRAY,
        build=lambda record, stamp, _frame_ms: convert.predictions_to_markers(record, stamp, style),
        read=lambda msg, _frame_ms: convert.markers_to_predictions(msg),
        encode=lambda record, stamp, _frame_ms: cdr.encode_predictions(record, stamp, style),
        decode=lambda data, _frame_ms: cdr_decode.decode_predictions(data),
        stamp=cdr_decode.marker_array_stamp_ms,
    )


def objects(style: MarkerStyle) -> Codec[Objects3D]:
    """3-D objects (detections, tracks) as CUBE markers in ``style``."""
    return Codec(
        _MARKER_ARRAY,
        build=lambda record, stamp, _frame_ms: convert.objects_to_markers(record, stamp, style),
        read=lambda msg, _frame_ms: convert.markers_to_objects(msg),
        encode=lambda record, stamp, _frame_ms: cdr.encode_objects(record, stamp, style),
        decode=lambda data, _frame_ms: cdr_decode.decode_objects(data),
        stamp=cdr_decode.marker_array_stamp_ms,
    )


def lanes(style: MarkerStyle) -> Codec[LaneGraph]:
    """A lane graph as LINE_STRIP lanes and TEXT_VIEW_FACING element labels in ``style``."""
    return Codec(
        _MARKER_ARRAY,
        build=lambda record, stamp, _frame_ms: convert.lanes_to_markers(record, stamp, style),
        read=lambda msg, _frame_ms: convert.markers_to_lanes(msg),
        encode=lambda record, stamp, _frame_ms: cdr.encode_lanes(record, stamp, style),
        decode=lambda data, _frame_ms: cdr_decode.decode_lanes(data),
        stamp=cdr_decode.marker_array_stamp_ms,
    )


#: A control command as labelled numbers (no common_interfaces type holds one).
CONTROL: Codec[ControlCommand] = Codec(
    "sensor_msgs/msg/JointState",
    build=lambda command, stamp, _frame_ms: convert.control_to_joint_state(command, stamp),
    read=lambda msg, _frame_ms: convert.joint_state_to_control(msg),
    encode=lambda command, stamp, _frame_ms: cdr.encode_control(command, stamp),
    decode=lambda data, _frame_ms: cdr_decode.decode_control(data),
    stamp=cdr_decode.header_stamp_ms,
)


#: JSON text on a std_msgs/String (metadata, frame markers, status); no stamp.
TEXT: Codec[str] = Codec(
    "std_msgs/msg/String",
    build=lambda text, _stamp, _frame_ms: convert.string_message(text),
    read=lambda msg, _frame_ms: convert.string_text(msg),
    encode=lambda text, _stamp, _frame_ms: cdr.encode_string(text),
    decode=lambda data, _frame_ms: cdr_decode.decode_string(data),
)

#: A log time on /clock; the record is the time itself.
CLOCK: Codec[int] = Codec(
    "rosgraph_msgs/msg/Clock",
    build=lambda stamp, _stamp, _frame_ms: convert.clock_message(stamp),
    read=lambda msg, _frame_ms: convert.clock_ms(msg),
    encode=lambda stamp, _stamp, _frame_ms: cdr.encode_clock(stamp),
    decode=lambda data, _frame_ms: cdr_decode.decode_clock(data),
)
