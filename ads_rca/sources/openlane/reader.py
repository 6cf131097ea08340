"""Reader for OpenLane-V2 segments: ``<split>/<segment>/info/<timestamp>.json``.

A lane-topology perception benchmark (Argoverse 2 as subset_A, nuScenes as subset_B): each
frame's info file holds the ego pose, lane centerlines in the ego frame, traffic elements
(lights and signs) as front-camera boxes, and the lane -> lane and lane -> element adjacency.
No actors, no plan, no crash (docs/formats.md "OpenLane-V2 segments" has the whole mapping):

- frames: one per info file, named by its timestamp. The unit is told by magnitude, once per
  segment from the median file name: at least :data:`NS_FROM` (1e17; Argoverse 2 stamps are
  ~3.2e17 ns) is nanoseconds, at least :data:`US_FROM` (1e14; nuScenes' ~1.5e15 µs) is
  microseconds, anything smaller is not an OpenLane-V2 segment (InputError). A file of the
  other magnitude is skipped and reported. Frames sit at their milliseconds since the
  segment's first timestamp (rounded; that stamp, in its unit, is the metadata's
  ``segment.first_timestamp``), so frame numbers count from 0 as a log's do rather than
  from the epoch; the frame period is the most common step. A step longer than 1.5 periods is a gap
  (reported; nuScenes' steps vary from 0.4 to 0.6 s, which are not).
- the ego: ``pose.rotation`` (3x3, ego -> city) and ``pose.translation`` of the right-handed
  city frame, mirrored into the model's left-handed one as the CARLA ROS bridge does
  (:mod:`ads_rca.sources.bag.profiles.frames`): y' = -y; the ZYX angles of R (roll = atan2(R21,
  R22),
  pitch = asin(-R20), yaw = atan2(R10, R00)) become roll' = roll, pitch' = -pitch,
  yaw' = -yaw, in degrees. The speed is *derived*: |Δtranslation| / Δt between neighbouring
  frames, the first frame taking the next difference.
- traffic elements: the ground truth's ``bboxes_gt`` (corners from ``points``; label,
  category and attribute names in the extras) and, with every lane, the frame's
  :class:`~ads_rca.sources.openlane.lanes.LaneGraph` in ``RunLog.lanes`` (lane points mirrored, y'
  = -y).
- a model's prediction (``--predictions DIR``): one ``<timestamp>.json`` per frame holding
  the annotation schema with confidences (bare, under ``annotation`` as an info file, or
  under ``predictions`` as the devkit's per-frame result): its traffic elements are the
  2-D detections (``bboxes``, score = confidence), its whole graph ``RunLog.lanes_predicted``.

Bad input is reported as the running-log reader does: a file that cannot be used (missing or
unusable pose, invalid JSON, not an object) skips its frame; a bad lane or element is dropped
with its topology row or column; a topology matrix of the wrong shape is read as no links.
Only a path that holds no usable segment raises InputError (one line).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from ads_rca.capabilities import source_statuses
from ads_rca.errors import InputError
from ads_rca.foundation.files import DEFAULT_MAX_FILE_MB, read_regular
from ads_rca.foundation.geometry import FloatArray
from ads_rca.model import (
    INPUTS_KEY,
    MAX_TIMESTAMP_MS,
    EgoPose,
    InputStatus,
    Record,
    RunLog,
    RunMetadata,
    most_common_step,
)
from ads_rca.problems import (
    IGNORED,
    KEPT_VALUE,
    SKIPPED_FILE,
    SKIPPED_FRAME,
    USED_DEFAULT,
    ProblemLog,
)
from ads_rca.sources.bag.profiles.frames import map_rpy_to_carla_deg
from ads_rca.sources.formats import SourceOptions
from ads_rca.sources.log.reader import UNUSABLE, check_max_file_mb, decode_file
from ads_rca.sources.openlane import INFO
from ads_rca.sources.openlane.annotation import (
    bounded_text,
    boxes_of,
    finite_array,
    lane_graph,
    shown,
    type_name,
)
from ads_rca.sources.openlane.lanes import LaneGraph

FORMAT_NAME = "openlane"
#: Timestamps at least this large are nanoseconds (Argoverse 2's are about 3.2e17).
NS_FROM = 10**17
#: Timestamps at least this large (and below :data:`NS_FROM`) are microseconds (nuScenes').
US_FROM = 10**14
#: Per unit: its name and the divisor taking it to milliseconds.
UNITS = {"ns": 1_000_000, "us": 1_000}
#: OpenLane-V2's frame period (2 Hz) when a segment has one frame.
DEFAULT_TPF = 500
#: A step this many frame periods long or longer leaves a frame out.
GAP_FACTOR = 1.5
#: At most this many info files are read from one segment (a real one has about 40).
MAX_FILES = 100_000
#: Largest |RᵀR − I| of a rotation used silently (JSON's rounded digits).
ORTHONORMAL_TOL = 1e-3
#: Largest |RᵀR − I| of a rotation still used (reported); past it the frame is skipped.
ROTATION_USABLE = 0.1
#: At most this many problem lines name files one by one for one kind of defect.
MAX_LISTED = 20
SOURCE_FRAME = (
    "OpenLane-V2 city and ego frames (right-handed: x forward, y left, z up) mirrored into "
    "the model's: y' = -y; roll' = roll, pitch' = -pitch, yaw' = -yaw (degrees, ZYX angles "
    "of pose.rotation)"
)
PREDICTION_KEYS = ("annotation", "predictions")


# --- the path ----------------------------------------------------------------------------


def info_folder(path: str | os.PathLike[str]) -> Path:
    """The ``info/`` folder of the segment at ``path`` (the segment folder or its ``info/``);
    InputError (one line) for anything else, naming a few segments of a dataset root or a
    split folder given instead."""
    given = Path(path)
    if not given.is_dir():
        raise InputError(f"{given}: not an OpenLane-V2 segment folder (<segment>/{INFO}/)")
    if given.name == INFO:
        return given
    if (given / INFO).is_dir():
        return given / INFO
    segments = _segments_under(given)
    if segments:
        shown = ", ".join(segments[:3]) + (", ..." if len(segments) > 3 else "")
        raise InputError(
            f"{given}: OpenLane-V2 data holding {len(segments)} segments ({shown}): "
            "give one segment folder"
        )
    raise InputError(f"{given}: not an OpenLane-V2 segment folder (no {INFO}/ folder)")


def _segments_under(root: Path) -> list[str]:
    """``split/segment`` (or ``segment``) of every segment folder in a dataset root or split
    folder, sorted, by names and ``stat`` only; empty for anything else."""
    found: list[str] = []
    for parent, prefix in [(root, ""), *((root / s, f"{s}/") for s in ("train", "val", "test"))]:
        try:
            names = sorted(os.listdir(parent)) if parent.is_dir() else []
        except OSError:
            continue
        found.extend(
            bounded_text(f"{prefix}{n}", "?")
            for n in names[:MAX_FILES]
            if (parent / n / INFO).is_dir()
        )
    return found


# --- the reader --------------------------------------------------------------------------


@dataclass(frozen=True)
class InfoFrame:
    """One usable info file: its time (ms), pose and annotation."""

    stamp_ms: int
    raw: int  # the file name's timestamp, in the segment's unit
    file: str
    rotation: FloatArray  # (3, 3) ego -> city, right-handed
    translation: FloatArray  # (3,) city, right-handed
    graph: LaneGraph
    document: Mapping[str, Any]


def read_openlane_segment(
    path: str | os.PathLike[str],
    max_file_mb: float = DEFAULT_MAX_FILE_MB,
    source: SourceOptions | None = None,
) -> RunLog:
    """Load one OpenLane-V2 segment (see the module docstring)."""
    source = source or SourceOptions()
    limit = check_max_file_mb(max_file_mb)
    folder = info_folder(path)
    problems = ProblemLog()
    raw_stamps = _listing(folder, INFO, problems)
    if not raw_stamps:
        raise InputError(f"{folder}: no <timestamp>.json info files")
    unit = timestamp_unit(list(raw_stamps))
    if unit is None:
        raise InputError(
            f"{folder}: timestamps like {_median(list(raw_stamps))} are neither nanoseconds "
            f"(>= 1e17) nor microseconds (>= 1e14)"
        )
    origin = min((raw for raw in raw_stamps if _unit_of(raw) == unit), default=0)
    stamps = _in_unit(raw_stamps, unit, origin, problems)
    frames: list[InfoFrame] = []
    for stamp_ms, (raw, name) in sorted(stamps.items()):
        frame = _read_info(folder / name, f"{INFO}/{name}", raw, stamp_ms, limit, problems)
        if frame is not None:
            frames.append(frame)
    frames = _usable_rotations(frames, problems)
    if not frames:
        raise InputError(f"{folder}: no usable info file ({_last(problems)})")
    log = _run_log(Path(path), folder, frames, unit, origin, problems)
    if source.predictions:
        _with_predictions(log, source.predictions, unit, origin, limit)
    return log


def timestamp_unit(stamps: Sequence[int]) -> str | None:
    """``ns``, ``us`` or None: the unit of a segment's timestamps, told by the median's
    magnitude (:data:`NS_FROM`, :data:`US_FROM`)."""
    return _unit_of(_median(stamps)) if stamps else None


def _unit_of(stamp: int) -> str | None:
    return "ns" if stamp >= NS_FROM else "us" if stamp >= US_FROM else None


def _median(stamps: Sequence[int]) -> int:
    return sorted(stamps)[len(stamps) // 2]


def _listing(folder: Path, label: str, problems: ProblemLog) -> dict[int, str]:
    """Raw timestamp -> file name of every ``<digits>.json`` in ``folder`` (``label`` in
    reports); others reported and ignored."""
    try:
        names = sorted(os.listdir(folder))
    except OSError as error:
        raise InputError(f"{folder}: cannot list: {error.strerror}") from None
    out: dict[int, str] = {}
    odd: list[str] = []
    for name in names:
        if not name.endswith(".json") or name.startswith("."):
            continue
        stem = name[: -len(".json")]
        if not (stem.isascii() and stem.isdigit() and len(stem) <= 30):
            odd.append(name)
            continue
        out.setdefault(int(stem), name)
    if odd:
        problems.add(
            f"{label}/{bounded_text(odd[0], '?')}",
            "file name",
            f"not <timestamp>.json ({len(odd)} such files)",
            IGNORED,
            "warning",
        )
    if len(out) > MAX_FILES:
        problems.add(f"{label}/", "", f"{len(out)} files: the first {MAX_FILES} read", IGNORED)
        out = dict(sorted(out.items())[:MAX_FILES])
    return out


def segment_ms(raw: int, unit: str, origin: int) -> int:
    """A timestamp in ``unit`` as milliseconds since the segment's first one (``origin``,
    same unit), rounded half up."""
    divisor = UNITS[unit]
    return (raw - origin + divisor // 2) // divisor


def _in_unit(
    raw_stamps: Mapping[int, str], unit: str, origin: int, problems: ProblemLog
) -> dict[int, tuple[int, str]]:
    """Milliseconds since ``origin`` -> (raw stamp, file name) of the files whose stamp is
    in ``unit`` and in range; the others (and a second file rounding to the same
    millisecond) reported."""
    out: dict[int, tuple[int, str]] = {}
    other: list[str] = []
    for raw, name in sorted(raw_stamps.items()):
        stamp_ms = segment_ms(raw, unit, origin)
        if _unit_of(raw) != unit or stamp_ms > MAX_TIMESTAMP_MS:
            other.append(name)
            continue
        if stamp_ms in out:
            problems.add(
                f"{INFO}/{name}",
                "file name",
                f"the same millisecond as {out[stamp_ms][1]}",
                "the earlier kept",
                "warning",
                stamp_ms,
            )
            continue
        out[stamp_ms] = (raw, name)
    if other:
        problems.add(
            f"{INFO}/{other[0]}",
            "file name",
            f"{len(other)} timestamps are not in the segment's unit ({unit}, from the median) "
            "or are past the latest time read",
            SKIPPED_FRAME,
        )
    return out


def _read_info(
    path: Path, file: str, raw: int, stamp_ms: int, limit: int, problems: ProblemLog
) -> InfoFrame | None:
    """One info file, or None (reported) when its frame cannot be used."""
    document = decode_file(read_regular(path, limit), file, problems, stamp_ms)
    if document is UNUSABLE:
        return None
    if not isinstance(document, dict):
        problems.add(file, "", f"expected an object, found {type_name(document)}", SKIPPED_FRAME)
        return None
    stated = document.get("timestamp")
    if stated is not None and stated != raw:
        problems.add(
            file,
            "timestamp",
            f"{shown(stated)} is not the file name's {raw}",
            "the file name's kept",
            "warning",
            stamp_ms,
        )
    pose = document.get("pose")
    rotation = finite_array(pose.get("rotation") if isinstance(pose, dict) else None, (3, 3))
    translation = finite_array(pose.get("translation") if isinstance(pose, dict) else None, (3,))
    if rotation is None or translation is None:
        what = (
            "missing" if not isinstance(pose, dict) else "no finite 3x3 rotation and 3 translation"
        )
        problems.add(file, "pose", what, SKIPPED_FRAME, "error", stamp_ms)
        return None
    annotation = document.get("annotation")
    if not isinstance(annotation, dict):
        problems.add(
            file, "annotation", "missing or not an object", "read as empty", "warning", stamp_ms
        )
        annotation = {}
    graph = lane_graph(annotation, file, "annotation", problems, stamp_ms, predicted=False)
    return InfoFrame(stamp_ms, raw, file, rotation, translation, graph, document)


def _usable_rotations(frames: list[InfoFrame], problems: ProblemLog) -> list[InfoFrame]:
    """The frames whose rotation is one: within :data:`ORTHONORMAL_TOL` silently, within
    :data:`ROTATION_USABLE` used as given (reported), else (or a reflection) skipped."""
    if not frames:
        return frames
    rotations = np.stack([f.rotation for f in frames])
    error = np.abs(np.einsum("nji,njk->nik", rotations, rotations) - np.eye(3)).max(axis=(1, 2))
    det = np.linalg.det(rotations)
    kept: list[InfoFrame] = []
    for frame, deviation, sign in zip(frames, error.tolist(), det.tolist(), strict=True):
        if deviation <= ORTHONORMAL_TOL and sign > 0:
            kept.append(frame)
            continue
        usable = deviation <= ROTATION_USABLE and sign > 0
        issue = f"not a rotation (max |RᵀR - I| = {deviation:.3g}, det {sign:.3g})"
        action = f"{KEPT_VALUE}: angles from its columns" if usable else SKIPPED_FRAME
        problems.add(frame.file, "pose.rotation", issue, action, "warning", frame.stamp_ms)
        if usable:
            kept.append(frame)
    return kept


def _last(problems: ProblemLog) -> str:
    found = list(problems)
    return f"{found[-1].file}: {found[-1].issue}" if found else "none found"


# --- the model ---------------------------------------------------------------------------


def ego_poses(
    rotations: FloatArray, translations: FloatArray, stamps_ms: Sequence[int]
) -> list[EgoPose]:
    """The ego per frame in the model's frame (see the module docstring), vectorised: the
    position and ZYX angles mirrored, the speed from neighbouring translations."""
    roll = np.arctan2(rotations[:, 2, 1], rotations[:, 2, 2])
    pitch = np.arcsin(np.clip(-rotations[:, 2, 0], -1.0, 1.0))
    yaw = np.arctan2(rotations[:, 1, 0], rotations[:, 0, 0])
    angles = map_rpy_to_carla_deg(np.stack([roll, pitch, yaw], axis=1)) + 0.0  # no -0.0
    position = np.stack([translations[:, 0], 0.0 - translations[:, 1], translations[:, 2]], axis=1)
    speed = np.full(len(stamps_ms), math.nan)
    if len(stamps_ms) >= 2:
        seconds = np.diff(np.asarray(stamps_ms, dtype=np.float64)) / 1000.0
        steps = np.linalg.norm(np.diff(translations, axis=0), axis=1) / seconds
        speed = np.concatenate([steps[:1], steps])
    return [
        EgoPose(x, y, z, roll_deg, pitch_deg, yaw_deg, v)
        for (x, y, z), (roll_deg, pitch_deg, yaw_deg), v in zip(
            position.tolist(), angles.tolist(), speed.tolist(), strict=True
        )
    ]


def _run_log(
    given: Path,
    folder: Path,
    frames: list[InfoFrame],
    unit: str,
    origin: int,
    problems: ProblemLog,
) -> RunLog:
    stamps = [f.stamp_ms for f in frames]
    frame_ms = most_common_step(stamps) or DEFAULT_TPF
    _report_gaps(stamps, frame_ms, problems)
    poses = ego_poses(
        np.stack([f.rotation for f in frames]), np.stack([f.translation for f in frames]), stamps
    )
    pose: dict[int, Record] = dict(zip(stamps, poses, strict=True))
    bboxes_gt: dict[int, Record] = {f.stamp_ms: boxes_of(f.graph, False) for f in frames}
    first = frames[0].document
    found = first.get("meta_data")
    meta: Mapping[str, Any] = found if isinstance(found, dict) else {}
    segment_name = folder.parent.name
    segment_id = bounded_text(first.get("segment_id"), "")
    if segment_id and segment_id != segment_name:
        problems.add(
            frames[0].file,
            "segment_id",
            f"{segment_id} is not the folder's name",
            "the folder's name shown",
            "warning",
        )
    total = stamps[-1] // frame_ms + 1
    raw: dict[str, Any] = {
        "source_format": FORMAT_NAME,
        "timesteps_per_frame": frame_ms,
        "collision_frame": -1,
        "total_frames": total,
        "source_frame": SOURCE_FRAME,
        "timestamp_unit": unit,
        "segment": {
            "id": bounded_text(segment_name, "?"),
            "segment_id": segment_id,
            "version": bounded_text(first.get("version"), ""),
            "source": bounded_text(meta.get("source"), ""),
            "source_id": bounded_text(meta.get("source_id"), ""),
            "frames": len(frames),
            "first_timestamp": origin,
        },
    }
    inputs = _capabilities(predicted=False)
    raw[INPUTS_KEY] = {key: status.to_dict() for key, status in inputs.items()}
    metadata = RunMetadata(frame_ms, (0.0, 0.0, 0.0), -1, total, raw)
    return RunLog.from_folders(
        metadata,
        tuple(stamps),
        {"pose": pose, "bboxes_gt": bboxes_gt},
        problems=problems,
        source=str(given),
        inputs=inputs,
        lanes={f.stamp_ms: f.graph for f in frames},
    )


def _report_gaps(stamps: Sequence[int], frame_ms: int, problems: ProblemLog) -> None:
    """Each step of at least :data:`GAP_FACTOR` periods, as the running-log reader says a
    gap (the first :data:`MAX_LISTED`, then a count)."""
    steps = np.diff(np.asarray(stamps, dtype=np.int64))
    gaps = np.flatnonzero(steps >= int(GAP_FACTOR * frame_ms)).tolist()
    for index in gaps[:MAX_LISTED]:
        start, end = stamps[index], stamps[index + 1]
        problems.add(
            f"{INFO}/",
            "timestamp",
            f"gap: no frame between {start} and {end} ms "
            f"(about {round((end - start) / frame_ms) - 1} missing)",
            "frames around the gap are analysed; the speed across it is an average",
            "warning",
            start,
        )
    if len(gaps) > MAX_LISTED:
        problems.add(
            f"{INFO}/", "timestamp", f"{len(gaps) - MAX_LISTED} more gaps", IGNORED, "warning"
        )


def _capabilities(predicted: bool, predictions: str = "") -> dict[str, InputStatus]:
    given = {
        "ego": InputStatus(
            "derived",
            f"{INFO}/*.json pose",
            "pose.rotation and pose.translation mirrored from the right-handed city frame; "
            "the speed derived from pose differences over the frame times (the first frame "
            "takes the next difference)",
        ),
        "ground_truth_2d": InputStatus(
            "real",
            f"{INFO}/*.json annotation.traffic_element",
            "traffic lights and signs as front-camera boxes; ids are the elements' (no actor "
            "carries them)",
        ),
        "actors": InputStatus(
            "absent",
            "",
            "OpenLane-V2 holds no actors (dynamic objects live in the parent Argoverse 2 or "
            "nuScenes data)",
        ),
        "collision": InputStatus("absent", "", "a perception benchmark: no collision recorded"),
        "clock": InputStatus("absent", "", "a segment has no clock topic"),
    }
    if predicted:
        given["detections_2d"] = InputStatus(
            "real",
            predictions,
            "a model's predicted traffic elements given with --predictions (score = confidence)",
        )
    else:
        given["detections_2d"] = InputStatus(
            "absent", "", "no --predictions folder of a model's per-frame results given"
        )
    return source_statuses(given, "an OpenLane-V2 segment holds no")


# --- predictions -------------------------------------------------------------------------


def _with_predictions(log: RunLog, directory: str, unit: str, origin: int, limit: int) -> None:
    """A model's per-frame results put in ``log``: ``bboxes`` and ``lanes_predicted``, the
    capability record and metadata saying where they came from."""
    root = Path(directory)
    if not root.is_dir():
        raise InputError(f"{root}: no such folder of prediction files")
    problems = ProblemLog()
    listed = _listing(root, root.name, problems)
    frames = set(log.frames)
    unmatched: list[str] = []
    for stamp, name in sorted(listed.items()):
        stamp_ms = segment_ms(stamp, unit, origin)
        file = f"{root.name}/{name}"
        if _unit_of(stamp) != unit or stamp_ms not in frames:
            unmatched.append(file)
            continue
        document = decode_file(read_regular(root / name, limit), file, problems, stamp_ms)
        if document is UNUSABLE:
            continue
        annotation, where = _prediction_annotation(document)
        if annotation is None:
            problems.add(
                file,
                "",
                "expected an annotation object (bare, or under annotation or predictions)",
                SKIPPED_FILE,
                "error",
                stamp_ms,
            )
            continue
        graph = lane_graph(annotation, file, where, problems, stamp_ms, predicted=True)
        log.lanes_predicted[stamp_ms] = graph
        log.bboxes[stamp_ms] = boxes_of(graph, True)
    if unmatched:
        problems.add(
            unmatched[0],
            "file name",
            f"{len(unmatched)} prediction files name no frame of the segment",
            IGNORED,
            "warning",
        )
    missing = [ts for ts in log.frames if ts not in log.lanes_predicted]
    if missing:
        problems.add(
            f"{root.name}/",
            "",
            f"{len(missing)} frames have no usable prediction (the first at {missing[0]} ms)",
            f"{USED_DEFAULT}: nothing predicted there",
            "warning",
        )
    log.problems.extend(problems)
    log.inputs.update(
        {k: v for k, v in _capabilities(True, os.fspath(directory)).items() if k == "detections_2d"}
    )
    raw = dict(log.metadata.raw)
    raw[INPUTS_KEY] = {name: s.to_dict() for name, s in log.inputs.items()}
    segment = dict(raw.get("segment") or {})
    segment["predicted_frames"] = len(log.lanes_predicted)
    raw["segment"] = segment
    log.metadata = replace(log.metadata, raw=raw)


def _prediction_annotation(document: object) -> tuple[Mapping[str, Any] | None, str]:
    """The annotation a prediction file holds and where (for problem fields)."""
    if not isinstance(document, dict):
        return None, ""
    for key in PREDICTION_KEYS:
        inner = document.get(key)
        if isinstance(inner, dict):
            return inner, key
    if "lane_centerline" in document or "traffic_element" in document:
        return document, "annotation"
    return None, ""
