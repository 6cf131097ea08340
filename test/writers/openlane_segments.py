"""OpenLane-V2 segments synthesised from the documented schema.

No info file of OpenLane-V2 is public in any repository (only the split index is), so the
fixtures write their own: ``write_openlane_segment(root, ...)`` writes
``<root>/<split>/<segment>/info/<timestamp>.json`` as the devkit's data README describes,
every value worked out by hand:

- timestamps in nanoseconds (subset_A, Argoverse 2: from :data:`NS_START`) or microseconds
  (subset_B, nuScenes: from :data:`US_START`), 0.5 s apart;
- the ego drives at :data:`SPEED` m/s along its heading :data:`YAW_DEG` (counter-clockwise
  from the city's x, right-handed) from (100, 200, 5), with pitch :data:`PITCH_DEG` and
  roll :data:`ROLL_DEG`: ``pose.rotation`` = Rz(yaw) Ry(pitch) Rx(roll);
- three lane centerlines in the ego frame (x forward, y left): ``A`` straight ahead from
  (0, 0) to (20, 0), ``B`` beside it on the left (y = 3.5), ``C`` continuing ``A`` to the
  left from (20, 0) to (30, 5); ``topology_lclc`` A -> C. Written as the released files
  hold lanes: :data:`RELEASED_POINTS` points (100 between each two of the three key
  points), so the official evaluation's thinning to every 20th point (11) keeps the key
  points (:func:`scored_points`);
- two traffic elements: a red light (category 1, attribute 1) at [[100, 200], [120, 260]]
  governing A, a go-straight sign (category 2, attribute 4) at [[300, 100], [340, 140]]
  governing B (``topology_lcte``);
- ids as integers (lanes 1, 2, 3; elements 10, 11) or as text (``lane-1`` ..., ``te-10``
  ...).

``write_openlane_predictions(folder, segment, variant)`` writes a model's per-frame results
for the same frames, one ``<timestamp>.json`` each, with its own ids (unique per frame only):
``perfect`` repeats the ground truth as the devkit scores it (the 11 points the official
evaluation keeps; confidence 0.9, true links 0.8 and the others 0.1), so
DET_l = DET_t = TOP_ll = TOP_lt = 1 and OLS = 1; ``missing_sign`` leaves out the sign and
its link, so DET_t is 0.5 (the red light's class found, go-straight's not) while DET_l stays
1. ``wrap`` chooses the document's shape: the devkit's per-frame result (``predictions``),
an info-like document (``annotation``) or the bare annotation.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

#: First timestamps (Argoverse 2's ns, nuScenes' µs) and the step of each unit.
NS_START = 315_967_376_859_927_000
US_START = 1_531_883_530_412_470
STEPS = {"ns": 500_000_000, "us": 500_000}
STARTS = {"ns": NS_START, "us": US_START}
SPEED = 10.0
YAW_DEG = 30.0
PITCH_DEG = 2.0
ROLL_DEG = 1.0
START = (100.0, 200.0, 5.0)
STEP_S = 0.5
LANES = {
    "A": [[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [20.0, 0.0, 0.0]],
    "B": [[0.0, 3.5, 0.0], [10.0, 3.5, 0.0], [20.0, 3.5, 0.0]],
    "C": [[20.0, 0.0, 0.0], [25.0, 1.5, 0.0], [30.0, 5.0, 0.0]],
}
ELEMENTS = (
    {"category": 1, "attribute": 1, "points": [[100.0, 200.0], [120.0, 260.0]]},
    {"category": 2, "attribute": 4, "points": [[300.0, 100.0], [340.0, 140.0]]},
)
#: Points per lane in the released info files.
RELEASED_POINTS = 201
#: Every this-many-th point is what the official val/test evaluation scores.
SCORED_EVERY = 20
LANE_LANE = [[0, 0, 1], [0, 0, 0], [0, 0, 0]]
LANE_ELEMENT = [[1, 0], [0, 1], [0, 0]]


def rotation(yaw_deg: float, pitch_deg: float, roll_deg: float) -> list[list[float]]:
    """Rz(yaw) Ry(pitch) Rx(roll), right-handed, as nested lists."""
    cy, sy = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    cp, sp = math.cos(math.radians(pitch_deg)), math.sin(math.radians(pitch_deg))
    cr, sr = math.cos(math.radians(roll_deg)), math.sin(math.radians(roll_deg))
    return [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]


def stamps(unit: str, frames: int) -> list[int]:
    """The frames' timestamps in ``unit`` (``ns`` or ``us``)."""
    return [STARTS[unit] + n * STEPS[unit] for n in range(frames)]


def position(frame: int) -> list[float]:
    """The ego's city position (right-handed) at a frame."""
    distance = SPEED * STEP_S * frame
    return [
        START[0] + distance * math.cos(math.radians(YAW_DEG)),
        START[1] + distance * math.sin(math.radians(YAW_DEG)),
        START[2],
    ]


def lane_ids(text_ids: bool) -> list[int | str]:
    return [f"lane-{n}" if text_ids else n for n in (1, 2, 3)]


def element_ids(text_ids: bool) -> list[int | str]:
    return [f"te-{n}" if text_ids else n for n in (10, 11)]


def released_points(key_points: list[list[float]]) -> list[list[float]]:
    """A lane of :data:`RELEASED_POINTS` points through its three key points (100 evenly
    spaced per leg)."""
    legs = len(key_points) - 1
    per_leg = (RELEASED_POINTS - 1) // legs
    out = []
    for leg in range(legs):
        start, end = key_points[leg], key_points[leg + 1]
        for step in range(per_leg):
            t = step / per_leg
            out.append([a + (b - a) * t for a, b in zip(start, end, strict=True)])
    out.append(list(key_points[-1]))
    return out


def scored_points(key_points: list[list[float]]) -> list[list[float]]:
    """What the official evaluation keeps of the released lane: every 20th point (11)."""
    return released_points(key_points)[::SCORED_EVERY]


def annotation(text_ids: bool) -> dict[str, Any]:
    """The ground truth of every frame (the scene ahead does not change)."""
    return {
        "lane_centerline": [
            {"id": ident, "points": released_points(points), "is_intersection_or_connector": False}
            for ident, points in zip(lane_ids(text_ids), LANES.values(), strict=True)
        ],
        "traffic_element": [
            {"id": ident, **element}
            for ident, element in zip(element_ids(text_ids), ELEMENTS, strict=True)
        ],
        "topology_lclc": LANE_LANE,
        "topology_lcte": LANE_ELEMENT,
    }


def info_document(segment: str, unit: str, frame: int, text_ids: bool) -> dict[str, Any]:
    """One frame's info file."""
    stamp = stamps(unit, frame + 1)[frame]
    source = "av2" if unit == "ns" else "nuscenes"
    return {
        "version": "v1.0",
        "segment_id": segment,
        "meta_data": {"source": source, "source_id": f"{source}-log-{segment}"},
        "timestamp": stamp,
        "sensor": {
            "ring_front_center": {
                "image_path": f"train/{segment}/image/ring_front_center/{stamp}.jpg",
                "extrinsic": {"rotation": rotation(0.0, 0.0, 0.0), "translation": [1.6, 0.0, 1.4]},
                "intrinsic": {
                    "K": [[1777.0, 0.0, 775.0], [0.0, 1777.0, 1024.0], [0.0, 0.0, 1.0]],
                    "distortion": [],
                },
            }
        },
        "pose": {
            "rotation": rotation(YAW_DEG, PITCH_DEG, ROLL_DEG),
            "translation": position(frame),
        },
        "annotation": annotation(text_ids),
    }


def write_openlane_segment(
    root: Path,
    segment: str = "00492",
    unit: str = "ns",
    frames: int = 6,
    text_ids: bool = False,
    split: str = "train",
) -> Path:
    """A segment's info files under ``root/split/segment/info/``; the segment folder."""
    info = root / split / segment / "info"
    info.mkdir(parents=True, exist_ok=True)
    for frame, stamp in enumerate(stamps(unit, frames)):
        document = info_document(segment, unit, frame, text_ids)
        (info / f"{stamp}.json").write_text(json.dumps(document), encoding="utf-8")
    return info.parent


def predicted_annotation(variant: str) -> dict[str, Any]:
    """A model's result for every frame (see the module docstring)."""
    lanes = [
        {"id": f"p{n}", "points": scored_points(points), "confidence": 0.9}
        for n, points in enumerate(LANES.values())
    ]
    keep = len(ELEMENTS) if variant == "perfect" else 1
    elements = [
        {"id": 100 + n, **element, "confidence": 0.9} for n, element in enumerate(ELEMENTS[:keep])
    ]
    return {
        "lane_centerline": lanes,
        "traffic_element": elements,
        "topology_lclc": [[0.8 if v else 0.1 for v in row] for row in LANE_LANE],
        "topology_lcte": [[0.8 if v else 0.1 for v in row[:keep]] for row in LANE_ELEMENT],
    }


def write_openlane_predictions(
    folder: Path,
    segment: Path,
    variant: str = "perfect",
    wrap: str = "predictions",
) -> Path:
    """A model's per-frame results for the frames of ``segment`` (``perfect`` or
    ``missing_sign``), wrapped as ``predictions``, ``annotation`` or bare; the folder."""
    folder.mkdir(parents=True, exist_ok=True)
    result = predicted_annotation(variant)
    for info in sorted((segment / "info").glob("*.json")):
        document = result if wrap == "bare" else {wrap: result}
        (folder / info.name).write_text(json.dumps(document), encoding="utf-8")
    return folder
