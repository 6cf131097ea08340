"""Writes a :class:`~ads_rca.model.RunLog` as an ADS running-log folder (the seed format).

Used by the scenario synthesiser and by ``ads-rca convert``. Output re-reads to the same
model: pose values are written as strings with the shortest round-tripping float repr,
numbers as JSON numbers, non-finite values as ``NaN``/``Infinity`` literals (as Python's
json module writes them, and as the reference reads them).
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import orjson

from ads_rca.foundation.strictjson import all_finite
from ads_rca.model import (
    ALL_FOLDERS,
    FILE_PREFIX,
    FOLDERS,
    Actors,
    Boxes,
    ControlCommand,
    EgoPose,
    Objects3D,
    Plan,
    Predictions,
    Record,
    RunLog,
)
from ads_rca.sources.openlane.annotation import annotation_document
from ads_rca.sources.openlane.lanes import LaneGraph


def write_run_log(log: RunLog, out_dir: str | os.PathLike[str]) -> Path:
    """Write every folder of ``log`` under ``out_dir`` (created); return the folder path."""
    root = Path(out_dir)
    root.mkdir(parents=True, exist_ok=True)
    _dump(root / "metadata.json", log.metadata_document(), finite=False)
    # By folder name: each folder holds its own record type.
    encoders: dict[str, Callable[[Any, int], object]] = {
        "pose": pose_document,
        "actors": lambda record, _ts: actors_document(record),
        "bboxes": lambda record, _ts: boxes_document(record),
        "bboxes_gt": lambda record, _ts: boxes_document(record),
        "predictions": lambda record, _ts: predictions_document(record),
        "predictions_with_perception": lambda record, _ts: predictions_document(record),
        "waypoint": lambda record, _ts: plan_document(record),
        "detections_3d": lambda record, _ts: objects_document(record),
        "tracks_3d": lambda record, _ts: objects_document(record),
        "control": lambda record, _ts: control_document(record),
        "lanes": lambda record, _ts: annotation_document(record, False),
        "lanes_predicted": lambda record, _ts: annotation_document(record, True),
    }
    for folder in ALL_FOLDERS:
        if folder not in FOLDERS and not log.folder(folder):
            continue  # an optional folder is written only when the log has its records
        directory = root / folder
        directory.mkdir(exist_ok=True)
        prefix = FILE_PREFIX[folder]
        for ts, record in log.folder(folder).items():
            document = encoders[folder](record, ts)
            _dump(directory / f"{prefix}-{ts}.json", document, record_is_finite(record))
    return root


def pose_document(pose: EgoPose, timestamp_ms: int) -> dict[str, str]:
    """The seed's pose file: every value a string."""
    return {
        "x": repr(pose.x),
        "y": repr(pose.y),
        "z": repr(pose.z),
        "pitch": repr(pose.pitch),
        "yaw": repr(pose.yaw),
        "roll": repr(pose.roll),
        "timestamp": str(timestamp_ms),
        "speed": repr(pose.speed),
    }


def actors_document(actors: Actors) -> dict[str, dict[str, dict[str, float]]]:
    loc, rot, ext = actors.location.tolist(), actors.rotation.tolist(), actors.extent.tolist()
    return {
        actor_id: {
            "extent": {"x": e[0], "y": e[1], "z": e[2]},
            "location": {"x": p[0], "y": p[1], "z": p[2]},
            "rotation": {"pitch": r[1], "roll": r[0], "yaw": r[2]},
        }
        for actor_id, p, r, e in zip(actors.ids, loc, rot, ext, strict=True)
    }


def boxes_document(boxes: Boxes) -> list[dict[str, object]]:
    return [
        {
            "id": json_id(box_id),
            "bounding_box": [[c[0], c[1]], [c[2], c[3]]],
            **extras,
        }
        for box_id, c, extras in zip(boxes.ids, boxes.corners.tolist(), boxes.extras, strict=True)
    ]


def predictions_document(predictions: Predictions) -> dict[str, dict[str, dict[str, float]]]:
    return {
        obstacle_id: {
            key: {"x": o[0], "y": o[1], "z": o[2]}
            for key, o in zip(track.keys, track.offsets.tolist(), strict=True)
        }
        for obstacle_id, track in predictions.items()
    }


def plan_document(plan: Plan) -> dict[str, dict[str, float]]:
    return {
        key: {"x": p[0], "y": p[1], "speed": s}
        for key, p, s in zip(plan.keys, plan.xy.tolist(), plan.speed.tolist(), strict=True)
    }


def objects_document(objects: Objects3D) -> dict[str, dict[str, object]]:
    """A ``detections_3d/`` or ``tracks_3d/`` file (strict JSON: NaN is written as null,
    which reads back as an unknown velocity or score, and is refused elsewhere)."""
    loc, ext, vel = (
        np.reshape(a, (-1, 3)).tolist()
        for a in (objects.location, objects.extent, objects.velocity)
    )
    return {
        object_id: {
            "location": {"x": p[0], "y": p[1], "z": p[2]},
            "rotation": {"yaw": yaw},
            "extent": {"x": e[0], "y": e[1], "z": e[2]},
            "velocity": {"x": v[0], "y": v[1], "z": v[2]},
            "score": score,
            "label": label,
        }
        for object_id, p, yaw, e, v, score, label in zip(
            objects.ids,
            loc,
            np.reshape(objects.yaw, -1).tolist(),
            ext,
            vel,
            np.reshape(objects.score, -1).tolist(),
            objects.labels,
            strict=True,
        )
    }


def control_document(command: ControlCommand) -> dict[str, float]:
    """A ``control/`` file (NaN written as null: unknown)."""
    return {"steer": command.steer, "acceleration": command.acceleration, "speed": command.speed}


def json_id(box_id: str) -> int | str:
    """Box ids are written as JSON integers when they are canonical integers (as the seed)."""
    if box_id.isdigit() and str(int(box_id)) == box_id:
        return int(box_id)
    return box_id


def _dump(path: Path, document: object, finite: bool = True) -> None:
    """Compact JSON; ``finite`` False when the record holds NaN or infinity."""
    if finite:
        path.write_bytes(orjson.dumps(document))
    else:  # orjson writes NaN as null; json writes the NaN literal the reader expects
        path.write_text(json.dumps(document))


def record_is_finite(record: Record) -> bool:
    """True when no number of a model record is NaN or infinite (checked on its arrays);
    always for the optional folders' records, whose files are strict JSON."""
    if isinstance(record, EgoPose):
        arrays = [np.array([getattr(record, f) for f in EgoPose.__dataclass_fields__])]
    elif isinstance(record, Actors):
        arrays = [record.location, record.rotation, record.extent]
    elif isinstance(record, Boxes):  # extras too: orjson would write their NaN as null
        arrays = [record.corners]
        if not all_finite(record.extras):
            return False
    elif isinstance(record, Plan):
        arrays = [record.xy, record.speed]
    elif isinstance(record, Objects3D | ControlCommand | LaneGraph):
        return True  # strict JSON: orjson writes NaN as the null these formats read back
    else:  # Predictions
        arrays = [track.offsets for track in record.values()]
    return all(bool(np.isfinite(a).all()) for a in arrays)
