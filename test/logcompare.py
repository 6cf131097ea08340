"""Field-by-field comparison of two RunLogs, with a tolerance for angles only.

Positions, sizes, speeds, ids, keys, extras and file order must be equal exactly (NaN equal
to NaN); angles may differ by ``angle_tol`` degrees modulo 360 (they go through quaternions),
except the yaw of 3-D objects, which the contract carries exactly.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from typing import TypeVar

import numpy as np
import numpy.typing as npt

from ads_rca.model import (
    ALL_FOLDERS,
    Actors,
    Boxes,
    ControlCommand,
    EgoPose,
    Objects3D,
    Plan,
    Predictions,
    RunLog,
)
from ads_rca.sources.openlane.lanes import LaneGraph

R = TypeVar("R")


def _exact(a: npt.ArrayLike, b: npt.ArrayLike, where: str) -> None:
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    assert a.shape == b.shape, f"{where}: shape {a.shape} != {b.shape}"
    assert np.array_equal(a, b, equal_nan=True), f"{where}: {a} != {b}"


def _angles(a: npt.ArrayLike, b: npt.ArrayLike, tol: float, where: str) -> None:
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    assert a.shape == b.shape, f"{where}: shape {a.shape} != {b.shape}"
    assert np.array_equal(np.isnan(a), np.isnan(b)), f"{where}: NaN pattern {a} != {b}"
    diff = np.abs((a - b + 180.0) % 360.0 - 180.0)
    worst = float(np.nanmax(diff)) if diff.size and not np.isnan(diff).all() else 0.0
    assert worst <= tol, f"{where}: angles differ by {worst} deg > {tol}: {a} != {b}"


def _pose(a: EgoPose, b: EgoPose, tol: float, where: str) -> None:
    _exact([a.x, a.y, a.z, a.speed], [b.x, b.y, b.z, b.speed], where)
    _angles([a.roll, a.pitch, a.yaw], [b.roll, b.pitch, b.yaw], tol, where)


def _actors(a: Actors, b: Actors, tol: float, where: str) -> None:
    assert a.ids == b.ids, f"{where}: ids {a.ids} != {b.ids}"
    _exact(a.location, b.location, f"{where} location")
    _exact(a.extent, b.extent, f"{where} extent")
    _angles(a.rotation, b.rotation, tol, f"{where} rotation")


def _boxes(a: Boxes, b: Boxes, where: str) -> None:
    assert a.ids == b.ids, f"{where}: ids {a.ids} != {b.ids}"
    _exact(a.corners, b.corners, f"{where} corners")
    # as JSON text: key order counts, and NaN equals NaN (it is never == itself)
    assert json.dumps(a.extras) == json.dumps(b.extras), where


def _predictions(a: Predictions, b: Predictions, where: str) -> None:
    assert list(a) == list(b), f"{where}: obstacle ids {list(a)} != {list(b)}"
    for key in a:
        assert a[key].keys == b[key].keys, f"{where}[{key}]: {a[key].keys} != {b[key].keys}"
        _exact(a[key].offsets, b[key].offsets, f"{where}[{key}]")


def _plan(a: Plan, b: Plan, where: str) -> None:
    assert a.keys == b.keys, f"{where}: keys {a.keys} != {b.keys}"
    _exact(a.xy, b.xy, f"{where} xy")
    _exact(a.speed, b.speed, f"{where} speed")


def _objects(a: Objects3D, b: Objects3D, where: str) -> None:
    assert a.ids == b.ids, f"{where}: ids {a.ids} != {b.ids}"
    assert a.labels == b.labels, f"{where}: labels {a.labels} != {b.labels}"
    for name in ("location", "yaw", "extent", "velocity", "score"):
        _exact(getattr(a, name), getattr(b, name), f"{where} {name}")


def _control(a: ControlCommand, b: ControlCommand, where: str) -> None:
    _exact([a.steer, a.acceleration, a.speed], [b.steer, b.acceleration, b.speed], where)


def _lanes(a: LaneGraph, b: LaneGraph, where: str) -> None:
    assert a.lane_ids == b.lane_ids, f"{where}: lane ids {a.lane_ids} != {b.lane_ids}"
    assert a.element_ids == b.element_ids, f"{where}: element ids"
    assert len(a.lanes) == len(b.lanes), f"{where}: lanes"
    for row, (x, y) in enumerate(zip(a.lanes, b.lanes, strict=True)):
        _exact(x, y, f"{where} lane {row}")
    for name in ("lane_scores", "element_boxes", "element_scores", "lane_lane", "lane_element"):
        _exact(getattr(a, name), getattr(b, name), f"{where} {name}")
    for name in ("element_category", "element_attribute"):
        assert getattr(a, name).tolist() == getattr(b, name).tolist(), f"{where} {name}"


def assert_logs_equal(
    a: RunLog, b: RunLog, angle_tol: float = 1e-9, *, check_frames: bool = True
) -> None:
    """Raise AssertionError naming the first difference between ``a`` and ``b``."""
    same = json.dumps(a.metadata.to_dict(), sort_keys=True) == json.dumps(
        b.metadata.to_dict(), sort_keys=True
    )
    assert same, "metadata differs"
    if check_frames:
        assert a.frames == b.frames, f"frames {a.frames} != {b.frames}"
    assert ALL_FOLDERS[0] == "pose" and ALL_FOLDERS[-1] == "lanes_predicted"  # this order
    _folder("pose", a.pose, b.pose, lambda x, y, w: _pose(x, y, angle_tol, w))
    _folder("actors", a.actors, b.actors, lambda x, y, w: _actors(x, y, angle_tol, w))
    _folder("bboxes", a.bboxes, b.bboxes, _boxes)
    _folder("bboxes_gt", a.bboxes_gt, b.bboxes_gt, _boxes)
    _folder("predictions", a.predictions, b.predictions, _predictions)
    pwp_a, pwp_b = a.predictions_with_perception, b.predictions_with_perception
    _folder("predictions_with_perception", pwp_a, pwp_b, _predictions)
    _folder("waypoint", a.waypoints, b.waypoints, _plan)
    _folder("detections_3d", a.detections_3d, b.detections_3d, _objects)
    _folder("tracks_3d", a.tracks_3d, b.tracks_3d, _objects)
    _folder("control", a.controls, b.controls, _control)
    _folder("lanes", a.lanes, b.lanes, _lanes)
    _folder("lanes_predicted", a.lanes_predicted, b.lanes_predicted, _lanes)


def _folder(
    name: str, fa: Mapping[int, R], fb: Mapping[int, R], same: Callable[[R, R, str], None]
) -> None:
    """One folder's records: the same timestamps, and ``same`` for each pair."""
    assert sorted(fa) == sorted(fb), f"{name}: stamps {sorted(fa)} != {sorted(fb)}"
    for ts in fa:
        same(fa[ts], fb[ts], f"{name}@{ts}")
