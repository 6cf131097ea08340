"""How a stack's topic carries one model input: its message type and its decoder.

Stack mode (the monitors beside a running stack, no player) reads the stack's own topics.
Each model input (a log folder: ``pose``, ``actors``, ``waypoint`` ...) comes on one topic in
one *layout*: ``contract`` (this project's message for that folder, decoded from CDR bytes by
the topic table's codec) or a common_interfaces message a stack publishes instead
(:mod:`ads_rca.contract.stack_inputs`):

======================= ========== ===========================================================
layout                  folder     message
======================= ========== ===========================================================
``contract``            every one  the contract's type for the folder (docs/topics.md)
``pose_stamped``        pose       geometry_msgs/PoseStamped, speed derived from successive poses
``path``                waypoint   nav_msgs/Path, speeds derived from the pose stamps
``carla_markers``       actors     the CARLA ROS bridge's CUBE markers (``/carla/markers``)
======================= ========== ===========================================================

A :class:`Decoder` turns one received message into ``(stamp_ms, record)``. It is an object
per input because a derived speed needs the pose before it; everything else is stateless.
The type names are text and message classes are imported on first use, so the table can be
read without rclpy; the input side stays open to the recordings issue's types (one row more).
Bad bytes or values raise :class:`~ads_rca.contract.errors.MalformedMessage` (CdrError is one).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ads_rca.contract import topics
from ads_rca.contract.convert import from_time
from ads_rca.contract.stack_inputs import (
    decode_carla_markers,
    path_to_plan,
    pose_stamped_pose,
)
from ads_rca.errors import ConfigError
from ads_rca.model import Record

CONTRACT = "contract"


@dataclass(frozen=True, slots=True)
class Layout:
    """One way a topic can carry a folder's records."""

    name: str
    type_name: str  #: ROS type, ``package/msg/Type``
    raw: bool  #: subscribed as CDR bytes (decoded by our codec), else as message objects
    derived: str = ""  #: what the layout does not carry and is derived ("" = nothing)


def contract_layout(folder: str) -> Layout:
    return Layout(CONTRACT, topics.MESSAGE_TYPE_NAMES[topics.FOLDER_TOPICS[folder]], raw=True)


#: The layouts other than ``contract``, by folder.
STACK_LAYOUTS: dict[str, dict[str, Layout]] = {
    "pose": {
        "pose_stamped": Layout(
            "pose_stamped",
            "geometry_msgs/msg/PoseStamped",
            raw=False,
            derived="ego speed from successive poses",
        )
    },
    "waypoint": {
        "path": Layout(
            "path", "nav_msgs/msg/Path", raw=False, derived="plan speeds from the pose stamps"
        )
    },
    "actors": {
        "carla_markers": Layout("carla_markers", "visualization_msgs/msg/MarkerArray", raw=True)
    },
}


def layouts(folder: str) -> dict[str, Layout]:
    """Every layout a folder can come in, ``contract`` first."""
    return {CONTRACT: contract_layout(folder), **STACK_LAYOUTS.get(folder, {})}


def layout(folder: str, name: str) -> Layout:
    """The layout ``name`` of ``folder``; ConfigError naming the known ones."""
    if folder not in topics.FOLDER_TOPICS:
        raise ConfigError(
            f"parameter inputs.{folder}: not a model input ({', '.join(topics.FOLDER_TOPICS)})"
        )
    known = layouts(folder)
    if name not in known:
        raise ConfigError(
            f"parameter inputs.{folder}.layout: {name!r} is not a layout of {folder} "
            f"({', '.join(known)})"
        )
    return known[name]


#: The ego pose record's numbers, checked on a reference pose's arrival.
POSE_NUMBERS = ("x", "y", "z", "roll", "pitch", "yaw", "speed")


class Decoder:
    """Reads one input's messages (``payload``: CDR bytes for a raw layout, else the message
    object) in two steps: :meth:`stamp_ms` on arrival (cheap: frames are formed by stamp)
    and :meth:`record` once the frame is released, in stamp order, when the frame period
    is known (contract predictions and plans are keyed in frame steps). NoStamp for a
    message without a stamp (an empty MarkerArray), MalformedMessage for one that cannot be
    read."""

    def __init__(self, folder: str, layout_name: str) -> None:
        self.folder = folder
        self.layout = layout(folder, layout_name)
        self._key = topics.FOLDER_TOPICS[folder]
        records: dict[str, Callable[[Any, int], Record]] = {
            CONTRACT: self._contract,
            "pose_stamped": self._pose_stamped,
            "path": path_to_plan,
            "carla_markers": lambda data, _frame_ms: decode_carla_markers(data),
        }
        self._record = records[self.layout.name]
        #: PoseStamped: the pose released before, for the derived speed.
        self._previous: Any = None

    def stamp_ms(self, payload: Any) -> int:
        if self.layout.raw:
            return topics.stamp_ms(self._key, payload)
        return from_time(payload.header.stamp)

    def record(self, payload: Any, timesteps_per_frame: int) -> Record:
        return self._record(payload, timesteps_per_frame)

    def pose_numbers(self, payload: Any) -> dict[str, float] | None:
        """An ego pose message's numbers by name, read on arrival (a reference pose is
        checked before it may define a frame); None for another input. MalformedMessage
        for a message that cannot be read."""
        if self.folder != "pose":
            return None
        if self.layout.name == CONTRACT:
            pose = self._contract(payload, 1)  # a pose reads no frame period
            return {name: getattr(pose, name) for name in POSE_NUMBERS}
        at = payload.pose
        return {
            "x": at.position.x,
            "y": at.position.y,
            "z": at.position.z,
            "qx": at.orientation.x,
            "qy": at.orientation.y,
            "qz": at.orientation.z,
            "qw": at.orientation.w,
        }

    def _contract(self, data: bytes, frame_ms: int) -> Record:
        return topics.decode_record(self._key, data, frame_ms)  # type: ignore[no-any-return]

    def _pose_stamped(self, msg: Any, _frame_ms: int) -> Record:
        """Speed over the interval from the pose released before (frames are released in
        stamp order; a dropped pose gives the mean over the longer interval)."""
        pose = pose_stamped_pose(msg, self._previous).pose
        self._previous = msg
        return pose


__all__ = ["CONTRACT", "Decoder", "Layout", "layout", "layouts"]
