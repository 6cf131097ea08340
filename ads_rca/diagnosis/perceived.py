"""A run without ground truth: the stack's own tracks stand in for the world.

Why: a real drive records no ground-truth actors, and every rule of `corrected` measures
against actors. Against what the stack itself perceived, three of the four modules can still
be judged as Autoware's own evaluators judge a drive: prediction against the later tracks
of the same objects (displacement at each horizon), planning against the perceived objects
(clearance, time to collision, whether braking would have been safe), the controller against
the plan. Perception cannot be judged against itself; it gets its own checks of what can be
seen without truth (:mod:`ads_rca.oracles.corrected.perception_without_truth`). Ground truth,
when the run has any, always wins: this only fills a run that has no actors.

The actors are the ego (from its pose, with the vehicle's size: the run's ``ego_size`` and
``ego_box_offset``, else :data:`DEFAULT_EGO_SIZE`) and every tracked object (its id,
centre, yaw and size) at each frame that has both; the run's metadata says
``reference: perceived`` and ``actors`` is ``derived`` from the tracks
(docs/real-drives.md).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import replace
from typing import Any

import numpy as np

from ads_rca.capabilities import input_status
from ads_rca.model import Actors, EgoPose, InputStatus, Objects3D, RunLog

#: Where the run's reference travels in its metadata, and its two values.
REFERENCE_KEY = "reference"
GROUND_TRUTH = "ground truth"
PERCEIVED = "perceived"
#: The ego's id among the derived actors (no tracker numbers an object so).
EGO_ID = "ego"
#: Full length, width, height (m) of the ego when the run gives none: Autoware's sample
#: vehicle (wheel base 2.79 m + front and rear overhangs 1.0 m and 1.1 m; tread 1.64 m +
#: 0.128 m each side).
DEFAULT_EGO_SIZE = (4.89, 1.896, 1.6)
#: How far ahead of the ego pose its box centre lies (m) when the run does not say: a pose
#: at the box centre (a simulator's); Autoware's base_link (rear axle) wants about 1.345.
DEFAULT_EGO_BOX_OFFSET = 0.0


def reference_of(log: RunLog) -> str:
    """``ground truth`` or ``perceived``: what the run's actors are."""
    return PERCEIVED if perceived_reference(log.metadata.raw) else GROUND_TRUTH


def perceived_reference(raw: Mapping[str, Any]) -> bool:
    """A run's metadata says its actors are its own tracks (a live monitor has only that)."""
    return raw.get(REFERENCE_KEY) == PERCEIVED


def is_perceived(log: RunLog) -> bool:
    return perceived_reference(log.metadata.raw)


def _number_triple(value: object, default: tuple[float, float, float]) -> tuple[float, ...]:
    if isinstance(value, list | tuple) and len(value) == 3:
        numbers = [v for v in value if isinstance(v, int | float) and not isinstance(v, bool)]
        if len(numbers) == 3 and all(math.isfinite(v) and v > 0 for v in numbers):
            return tuple(float(v) for v in numbers)
    return default


def ego_size(raw: Mapping[str, Any]) -> tuple[float, ...]:
    """The ego's full length, width and height (m): the run's ``ego_size`` when well formed."""
    return _number_triple(raw.get("ego_size"), DEFAULT_EGO_SIZE)


def ego_box_offset(raw: Mapping[str, Any]) -> float:
    value = raw.get("ego_box_offset", DEFAULT_EGO_BOX_OFFSET)
    if isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value):
        return float(value)
    return DEFAULT_EGO_BOX_OFFSET


def perceived_world(log: RunLog) -> RunLog:
    """``log`` with actors made of its tracked objects when it has no ground truth (the same
    log when it has actors, or no tracks to make them of)."""
    if log.actors or not log.tracks_3d or not log.pose:
        return log
    half = np.asarray(ego_size(log.metadata.raw), dtype=np.float64) / 2.0
    offset = ego_box_offset(log.metadata.raw)
    actors: dict[int, Actors] = {}
    for ts, tracks in log.tracks_3d.items():
        pose = log.pose.get(ts)
        if pose is not None:
            actors[ts] = _frame_actors(pose, tracks, half, offset)
    if not actors:
        return log
    inputs = input_status(log)  # a log folder's statuses come from its records: keep them
    source = inputs.get("tracked_objects")
    inputs["actors"] = InputStatus(
        "derived",
        f"the stack's tracked objects ({source.source})" if source and source.source else "tracks",
        "no ground truth: the stack's own tracks stand in for the world",
    )
    metadata = replace(log.metadata, raw={**log.metadata.raw, REFERENCE_KEY: PERCEIVED})
    frames = tuple(ts for ts in sorted(actors))
    return replace(log, metadata=metadata, actors=actors, frames=frames, inputs=inputs)


def _frame_actors(pose: EgoPose, tracks: Objects3D, half: np.ndarray, offset: float) -> Actors:
    """The ego (first row, box centre ``offset`` ahead of its pose) and every track."""
    yaw = math.radians(pose.yaw)
    centre = np.array(
        [pose.x + offset * math.cos(yaw), pose.y + offset * math.sin(yaw), pose.z],
        dtype=np.float64,
    )
    n = len(tracks.ids)
    location = np.empty((n + 1, 3))
    location[0] = centre
    location[1:] = tracks.location
    rotation = np.zeros((n + 1, 3))
    rotation[0] = (pose.roll, pose.pitch, pose.yaw)
    rotation[1:, 2] = tracks.yaw
    extent = np.empty((n + 1, 3))
    extent[0] = half
    extent[1:] = tracks.extent
    ids = (EGO_ID, *(EGO_ID + "'" if i == EGO_ID else i for i in tracks.ids))
    return Actors(ids, location, rotation, extent)
