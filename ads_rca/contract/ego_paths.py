"""``run/ego_paths``: one snapshot row's future ego paths, as JSON on a ``std_msgs/String``.

A table of independent snapshots (atmaCup #18, ``ads_rca.sources.atmacup.snapshots``) has, per row,
a
realised future ego path and perhaps a model's predicted one; neither fits a per-frame
topic of the seed format (a plan has no z and points into other rows). The player sends,
with each row's frame and before its ``run/frame`` marker, one message:

``{"stamp_ms", "id", "row", "horizons_s", "realised", "predicted", "submission", "run"}``

with ``realised`` / ``predicted`` six ``[x, y, z]`` points (the model's frame at the row's
moment: y mirrored, metres) or null where there is none. A live trajectory-prediction model
(any node on the run's graph, in its own process) may send the same message with only
``stamp_ms``, ``id`` and ``predicted``, its ``submission`` (a name for itself) and the
``run`` it answers (the player's messages name it). The messages of one stamp are merged,
a path given later replacing an earlier one (:func:`merged`): the aggregator scores the
run's rows so at its verdict as ``diagnose`` scores the table
(``ads_rca.sources.atmacup.trajectory_scores``), and the planning monitor scores each row frame by
frame;
a model usually answers after it heard the frame, so when its path comes after the monitor
judged the row, the row's planning result is published again with ``revision`` + 1
(``ads_rca.live.row_paths``: the rule and its bounds). A message of another run is dropped;
one that cannot be read (a field of the wrong type, text over :data:`MAX_TEXT`, a
coordinate beyond :data:`MAX_COORDINATE_M`) is skipped and said.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ads_rca.contract.errors import MalformedMessage
from ads_rca.foundation.geometry import FloatArray
from ads_rca.model import MAX_TIMESTAMP_MS, RunLog
from ads_rca.sources.atmacup.snapshots import HORIZONS_S, EgoSnapshots

#: The longest row ID or submission name a message may carry.
MAX_TEXT = 256
#: The largest coordinate (metres, either sign) a path may have: a path 3 s ahead further
#: than this is no path (and its squares would overflow the scores).
MAX_COORDINATE_M = 1e6


def ego_path_document(log: RunLog, timestamp_ms: int) -> dict[str, Any] | None:
    """The message document of the row played at ``timestamp_ms`` (None: no such row)."""
    snapshots = log.ego_snapshots
    row = snapshots.row_at(timestamp_ms) if snapshots is not None else None
    if snapshots is None or row is None:
        return None
    return {
        "stamp_ms": timestamp_ms,
        "id": snapshots.ids[row],
        "row": int(snapshots.file_rows[row]),
        "horizons_s": list(HORIZONS_S),
        "realised": _points(snapshots.realised[row]),
        "predicted": _points(snapshots.predicted[row]),
        "submission": snapshots.submission,
    }


def _points(path: FloatArray) -> list[list[float]] | None:
    return None if np.isnan(path).all() else path.tolist()


@dataclass(frozen=True)
class EgoPathRow:
    """One received row: its stamp, ID, table row (-1 unknown) and the paths it gave."""

    stamp_ms: int
    ident: str
    row: int
    realised: FloatArray | None
    predicted: FloatArray | None
    submission: str


def read_ego_path(document: dict[str, Any]) -> EgoPathRow:
    """A ``run/ego_paths`` document checked field by field; MalformedMessage naming the
    field otherwise."""
    stamp = document.get("stamp_ms")
    if not isinstance(stamp, int) or isinstance(stamp, bool) or not 0 <= stamp <= MAX_TIMESTAMP_MS:
        raise MalformedMessage("run/ego_paths: stamp_ms is not a timestamp")
    ident = document.get("id", "")
    submission = document.get("submission", "")
    row = document.get("row", -1)
    if not isinstance(ident, str) or not isinstance(submission, str):
        raise MalformedMessage("run/ego_paths: id and submission must be text")
    if len(ident) > MAX_TEXT or len(submission) > MAX_TEXT:
        raise MalformedMessage(f"run/ego_paths: id or submission longer than {MAX_TEXT}")
    if not isinstance(row, int) or isinstance(row, bool) or not -1 <= row <= MAX_TIMESTAMP_MS:
        raise MalformedMessage("run/ego_paths: row is not an integer from -1 up")
    return EgoPathRow(
        stamp,
        ident,
        row,
        _path(document.get("realised"), "realised"),
        _path(document.get("predicted"), "predicted"),
        submission,
    )


def _path(value: object, name: str) -> FloatArray | None:
    if value is None:
        return None
    shape = (len(HORIZONS_S), 3)
    if not (
        isinstance(value, list)
        and len(value) == shape[0]
        and all(isinstance(p, list) and len(p) == 3 for p in value)
        and all(isinstance(v, int | float) and not isinstance(v, bool) for p in value for v in p)
    ):
        raise MalformedMessage(f"run/ego_paths: {name} is not six [x, y, z] points")
    out: FloatArray = np.asarray(value, dtype=np.float64).reshape(shape)
    if not (np.abs(out) <= MAX_COORDINATE_M).all():  # NaN fails too
        raise MalformedMessage(
            f"run/ego_paths: {name} has a coordinate beyond {MAX_COORDINATE_M:g} m"
        )
    return out


def snapshots_from_rows(rows: dict[int, EgoPathRow]) -> EgoSnapshots:
    """The rows received (merged per stamp), in stamp order, as the run's snapshots."""
    ordered = [rows[stamp] for stamp in sorted(rows)]
    shape = (len(ordered), len(HORIZONS_S), 3)
    realised, predicted = np.full(shape, np.nan), np.full(shape, np.nan)
    for n, got in enumerate(ordered):
        if got.realised is not None:
            realised[n] = got.realised
        if got.predicted is not None:
            predicted[n] = got.predicted
    return EgoSnapshots(
        tuple(r.ident for r in ordered),
        np.array([r.stamp_ms for r in ordered], dtype=np.int64),
        np.array([r.row for r in ordered], dtype=np.int64),
        realised,
        predicted,
        submission=next((r.submission for r in ordered if r.submission), ""),
    )


def merged(earlier: EgoPathRow | None, later: EgoPathRow) -> EgoPathRow:
    """Two messages of one stamp as one: each path and text from the later where it has
    one, else the earlier's."""
    if earlier is None:
        return later
    return EgoPathRow(
        later.stamp_ms,
        later.ident or earlier.ident,
        later.row if later.row >= 0 else earlier.row,
        later.realised if later.realised is not None else earlier.realised,
        later.predicted if later.predicted is not None else earlier.predicted,
        later.submission or earlier.submission,
    )
