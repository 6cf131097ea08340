"""A tiny builder of RunLogs for hand-computed oracle tests (no files, no reader).

Why: oracle tests need a handful of poses, actors, boxes, predictions and plans at chosen
timestamps, with every other folder deliberately absent; writing the model dataclasses by
hand in each test would bury the numbers that matter.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ads_rca.model import Actors, Boxes, EgoPose, Plan, RunLog, RunMetadata, Track
from ads_rca.oracles.base import RunContext
from ads_rca.params import make_params

XY = tuple[float, float]
CAR = (2.4, 1.0, 0.75)


class LogBuilder:
    """Collects per-timestamp records, then :meth:`build` makes the RunLog."""

    def __init__(
        self,
        frame_ms: int = 50,
        total_frames: int = 20,
        camera_loc: tuple[float, float, float] = (1.3, 0.0, 1.8),
        collision_frame: int = -1,
    ) -> None:
        self.metadata = RunMetadata(frame_ms, camera_loc, collision_frame, total_frames)
        self.frames: list[int] = []
        self._actors: dict[int, dict[str, tuple[XY, float, Sequence[float]]]] = {}
        self.log = RunLog(metadata=self.metadata, frames=())

    def frame(self, *timestamps: int) -> LogBuilder:
        self.frames.extend(timestamps)
        return self

    def pose(self, ts: int, x: float, y: float, yaw: float = 0.0) -> LogBuilder:
        self.log.pose[ts] = EgoPose(x, y, 0.0, 0.0, 0.0, yaw, 0.0)
        return self

    def actor(
        self,
        ts: int,
        actor_id: str,
        x: float,
        y: float,
        ext: Sequence[float] = CAR,
        yaw: float = 0.0,
    ) -> LogBuilder:
        self._actors.setdefault(ts, {})[actor_id] = ((x, y), yaw, ext)
        return self

    def no_actors_file(self, ts: int) -> LogBuilder:
        """An actors record with no actors at all would still be a file; drop it."""
        self._actors.pop(ts, None)
        return self

    def boxes(
        self,
        ts: int,
        det: Sequence[tuple[str, Sequence[float]]] | None,
        gt: Sequence[tuple[str, Sequence[float]]] | None,
    ) -> LogBuilder:
        for folder, items in ((self.log.bboxes, det), (self.log.bboxes_gt, gt)):
            if items is not None:
                folder[ts] = make_boxes(items)
        return self

    def on_truth(self, ts: int, tracks: Mapping[str, Mapping[str, XY]]) -> LogBuilder:
        self.log.predictions_with_perception[ts] = make_predictions(tracks)
        return self

    def raw(self, ts: int, tracks: Mapping[str, Mapping[str, XY]]) -> LogBuilder:
        self.log.predictions[ts] = make_predictions(tracks)
        return self

    def plan(self, ts: int, points: Mapping[str, XY]) -> LogBuilder:
        keys = tuple(points)
        xy = np.array([points[k] for k in keys], dtype=np.float64).reshape(-1, 2)
        self.log.waypoints[ts] = Plan(keys, xy, np.zeros(len(keys)))
        return self

    def build(self) -> RunLog:
        for ts, actors in self._actors.items():
            ids = tuple(actors)
            loc = np.array([[*actors[a][0], 0.0] for a in ids], dtype=np.float64).reshape(-1, 3)
            rot = np.array([[0.0, 0.0, actors[a][1]] for a in ids]).reshape(-1, 3)
            ext = np.array([list(actors[a][2]) for a in ids], dtype=np.float64).reshape(-1, 3)
            self.log.actors[ts] = Actors(ids, loc, rot, ext)
        self.log.actors = dict(sorted(self.log.actors.items()))
        self.log.frames = tuple(sorted(self.frames))
        return self.log


def make_boxes(items: Sequence[tuple[str, Sequence[float]]]) -> Boxes:
    ids = tuple(i for i, _ in items)
    corners = np.array([list(c) for _, c in items], dtype=np.float64).reshape(-1, 4)
    return Boxes(ids, corners, tuple({} for _ in items))


def make_predictions(tracks: Mapping[str, Mapping[str, XY]]) -> dict[str, Track]:
    out: dict[str, Track] = {}
    for obstacle_id, steps in tracks.items():
        keys = tuple(steps)
        offsets = np.array([[*steps[k], 0.0] for k in keys], dtype=np.float64).reshape(-1, 3)
        out[obstacle_id] = Track(keys, offsets)
    return out


def context(log: RunLog, **overrides: Any) -> RunContext:
    """A reference-mode context (ego found by the reference's rule at 50 ms)."""
    return RunContext.create(log, make_params("reference", overrides))
