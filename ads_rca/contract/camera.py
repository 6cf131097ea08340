"""The run's camera for 3D viewers: its mounting on the ego, and its pinhole model when known.

The detections and ground-truth boxes are pixel rectangles in frame ``camera_image``. A 3D
view (Foxglove, RViz) can only place them once it knows where that frame is and how pixels
map to rays, so the player sends, once and latched:

- ``/tf_static``: ``base_link`` → ``camera_image`` (:func:`camera_mount`), the translation
  being ``ego_config.camera.camera_loc`` in REP-103 axes (x, −y, z) and the rotation the
  ROS optical convention (z forward along the ego's x, x right, y down): the log format
  gives the camera's position only, and its camera looks along the ego's x axis (as the
  reference's gap rule and our synthesiser assume);
- ``camera/camera_info`` (:func:`camera_intrinsics`), only when ``ego_config.camera`` also
  has CARLA's camera attributes ``image_size_x``, ``image_size_y`` and ``fov`` (horizontal,
  degrees): CARLA's pinhole, f = width / (2 tan(fov / 2)), principal point at the image
  centre, no distortion. The seed format has no intrinsics, so most logs get no CameraInfo.

Pure data: the messages are built by :func:`ads_rca.contract.cdr.encode_tf_message` and
:func:`ads_rca.contract.convert.camera_info_message`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ads_rca.contract.convert import EGO_FRAME, IMAGE_FRAME
from ads_rca.model import RunMetadata

#: Rotation base_link → optical frame (x, y, z, w): z along the body's x, x along −y
#: (right), y along −z (down); the rotation RPY (−90°, 0, −90°) of the ROS camera convention.
OPTICAL_ROTATION: tuple[float, float, float, float] = (-0.5, 0.5, -0.5, 0.5)

#: The metadata keys of the camera's intrinsics (CARLA's camera blueprint attributes).
INTRINSIC_KEYS = ("image_size_x", "image_size_y", "fov")


@dataclass(frozen=True, slots=True)
class StaticTransform:
    """One geometry_msgs/TransformStamped of ``/tf_static``."""

    parent: str
    child: str
    translation: tuple[float, float, float]
    rotation: tuple[float, float, float, float]  # x, y, z, w


@dataclass(frozen=True, slots=True)
class Intrinsics:
    """A distortion-free pinhole camera (what sensor_msgs/CameraInfo needs)."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    @property
    def k(self) -> tuple[float, ...]:
        """The 3×3 camera matrix, row-major."""
        return (self.fx, 0.0, self.cx, 0.0, self.fy, self.cy, 0.0, 0.0, 1.0)

    @property
    def p(self) -> tuple[float, ...]:
        """The 3×4 projection matrix of a monocular camera, row-major."""
        return (self.fx, 0.0, self.cx, 0.0, 0.0, self.fy, self.cy, 0.0, 0.0, 0.0, 1.0, 0.0)


def camera_mount(metadata: RunMetadata) -> StaticTransform:
    """``base_link`` → ``camera_image`` from ``camera_loc`` (CARLA body axes → REP-103).

    Raises ValueError when the position is not finite (a value the reader read as NaN).
    """
    x, y, z = metadata.camera_loc
    if not all(math.isfinite(v) for v in (x, y, z)):
        raise ValueError(f"ego_config.camera.camera_loc: {[x, y, z]} is not a finite position")
    return StaticTransform(
        EGO_FRAME, IMAGE_FRAME, (float(x), -float(y), float(z)), OPTICAL_ROTATION
    )


def camera_intrinsics(metadata: RunMetadata) -> Intrinsics | None:
    """The camera's pinhole model, or None when the metadata does not give it.

    Raises ValueError naming the field when the keys are there but unusable.
    """
    camera = _camera_document(metadata.raw)
    if not all(key in camera for key in INTRINSIC_KEYS):
        return None
    width, height = (_positive_int(camera, key) for key in INTRINSIC_KEYS[:2])
    fov = _number(camera, "fov")
    if not 0.0 < fov < 180.0:
        raise ValueError(f"ego_config.camera.fov: {fov!r} is not an angle in (0, 180) degrees")
    focal = width / (2.0 * math.tan(math.radians(fov) / 2.0))
    return Intrinsics(width, height, focal, focal, width / 2.0, height / 2.0)


def _camera_document(document: Mapping[str, Any]) -> Mapping[str, Any]:
    ego_config = document.get("ego_config")
    camera = ego_config.get("camera") if isinstance(ego_config, Mapping) else None
    return camera if isinstance(camera, Mapping) else {}


def _number(camera: Mapping[str, Any], key: str) -> float:
    """A number, or a string holding one (CARLA attributes are strings)."""
    value = camera[key]
    try:
        if isinstance(value, bool) or not isinstance(value, int | float | str):
            raise ValueError
        number = float(value)
    except ValueError:
        raise ValueError(f"ego_config.camera.{key}: {value!r} is not a number") from None
    if not math.isfinite(number):
        raise ValueError(f"ego_config.camera.{key}: {value!r} is not a finite number")
    return number


def _positive_int(camera: Mapping[str, Any], key: str) -> int:
    number = _number(camera, key)
    if number != int(number) or not 0 < number <= 1 << 20:
        raise ValueError(f"ego_config.camera.{key}: {camera[key]!r} is not a pixel count")
    return int(number)
