"""Deterministic synthetic RunLogs that exercise every corner of the ROS topic contract.

Built in code (no reader needed): all seven folders, numeric and non-numeric ids, extras on
boxes, step keys out of order, an empty predictions record, missing files, and optionally
a duplicated analysed frame and records-only stamps (a pose with no actors file).
:func:`add_3d` adds the optional folders (3-D detections, tracks, control commands, lane
graphs: ground truth and predicted); :func:`awkward_log` is the log with every extreme value
the contract must carry, and :func:`play_through_assembler` feeds everything a player would
send for a log to an assembler.
"""

from __future__ import annotations

import zlib

import numpy as np

from ads_rca.contract import convert, playback, topics
from ads_rca.contract.assembler import RunLogAssembler
from ads_rca.model import (
    Actors,
    Boxes,
    ControlCommand,
    EgoPose,
    Objects3D,
    Plan,
    RunLog,
    RunMetadata,
    Track,
)
from ads_rca.sources.openlane.lanes import LaneGraph

TPF = 50


def _actor_ids(rng: np.random.Generator, n: int) -> tuple[str, ...]:
    special = ["walker_3", "4294967296", "0042", "vehicle.tesla"]
    ids: list[str] = []
    for i in range(n):
        if i % 7 == 3 and special:
            ids.append(special.pop(0))
        else:
            ids.append(str(int(rng.integers(100, 100_000)) * 10 + i))
    return tuple(ids)


def make_log(
    n_frames: int,
    n_actors: int,
    seed: int = 0,
    *,
    duplicate_frame: bool = False,
    orphan_stamps: bool = False,
    empty_predictions: bool = True,
) -> RunLog:
    """A valid RunLog of ``n_frames`` frames (frame_ms 50 ms) with ``n_actors`` actors."""
    rng = np.random.default_rng(seed)
    ids = _actor_ids(rng, n_actors)
    frames = [TPF * (f + 1) for f in range(n_frames)]
    if duplicate_frame and n_frames > 2:
        frames.insert(2, frames[1])
    metadata = RunMetadata(
        timesteps_per_frame=TPF,
        camera_loc=(1.3, 0.0, 1.8),
        collision_frame=n_frames,
        total_frames=n_frames,
        raw={"timesteps_per_frame": TPF, "scenario": "factory", "ego_config": {"x": 1}},
    )
    log = RunLog(metadata=metadata, frames=tuple(frames), source=f"factory-{seed}")
    for f, ts in enumerate(dict.fromkeys(frames)):
        if f % 5 != 4:  # pose missing every fifth frame
            roll, pitch, yaw = rng.uniform(-179.9, 179.9, 3) * np.array([0.1, 0.2, 1.0])
            log.pose[ts] = EgoPose(
                x=float(rng.normal(-100, 30)),
                y=float(rng.normal(3, 5)),
                z=float(rng.uniform(0, 0.1)),
                roll=float(roll),
                pitch=float(pitch),
                yaw=float(yaw),
                speed=float(rng.uniform(0, 20)),
            )
        rotation = np.column_stack(
            (
                rng.uniform(-5, 5, n_actors),
                rng.uniform(-30, 30, n_actors),
                rng.uniform(-179.999, 179.999, n_actors),
            )
        )
        extent = rng.uniform(0.2, 3.0, (n_actors, 3))
        if n_actors > 1 and f % 3 == 0:
            extent[1] = np.nan
        log.actors[ts] = Actors(
            ids=ids,
            location=rng.normal(0, 50, (n_actors, 3)),
            rotation=rotation,
            extent=extent,
        )
        if f % 4 != 3:  # bboxes missing every fourth frame
            log.bboxes[ts] = _boxes(rng, ids[: max(0, n_actors - 1)], detected=True)
        log.bboxes_gt[ts] = _boxes(rng, ids, detected=False)
        log.predictions[ts] = {} if empty_predictions and f % 6 == 2 else _predictions(rng, ids)
        if f % 7 != 5:
            log.predictions_with_perception[ts] = _predictions(rng, ids[::-1])
        if f % 8 != 7:
            log.waypoints[ts] = _plan(rng, shuffled=f % 2 == 1)
    if orphan_stamps:
        last = frames[-1]
        log.pose[last + TPF] = EgoPose(1.0, -2.0, 0.0, 0.0, 1.5, -90.0, 3.0)
        log.waypoints[TPF // 2] = _plan(rng, shuffled=False)
    return log


def _boxes(rng: np.random.Generator, ids: tuple[str, ...], *, detected: bool) -> Boxes:
    n = len(ids)
    p1 = rng.uniform(0, 1200, (n, 2)).round(1)
    p2 = p1 + rng.uniform(-200, 300, (n, 2)).round(3)  # not normalised: x2 may be < x1
    corners = np.hstack((p1, p2))
    extras: list[dict[str, object]] = []
    for i in range(n):
        if not detected:
            extras.append({})
        elif i % 3 == 0:
            extras.append({"score": float(rng.uniform()), "label": "car"})
        elif i % 3 == 1:
            extras.append({"label": "walker", "score": 0.9, "attrs": {"occluded": True}})
        else:
            extras.append({"label": "car"})
    box_ids = tuple(f"det_{i}" if detected and i % 4 == 1 else str(i) for i in range(n))
    return Boxes(ids=box_ids if detected else ids, corners=corners, extras=tuple(extras))


def _predictions(rng: np.random.Generator, ids: tuple[str, ...]) -> dict[str, Track]:
    out: dict[str, Track] = {}
    for obstacle in ids[: min(len(ids), 6)]:
        keys = [str(k) for k in range(int(rng.integers(1, 8)))]
        if len(keys) > 2:
            keys[0], keys[-1] = keys[-1], keys[0]  # out of order, as some logs have it
        out[obstacle] = Track(keys=tuple(keys), offsets=rng.normal(0, 10, (len(keys), 3)))
    return out


def _plan(rng: np.random.Generator, *, shuffled: bool) -> Plan:
    keys = [str(k) for k in range(10)]
    if shuffled:
        keys = keys[5:] + keys[:5]
    return Plan(keys=tuple(keys), xy=rng.normal(0, 100, (10, 2)), speed=rng.uniform(0, 20, 10))


def lane_graph(rng: np.random.Generator, lanes: int, elements: int, predicted: bool) -> LaneGraph:
    """A lane graph as OpenLane-V2 gives one (so a log folder's files read it back): lanes of
    2 to 6 points, ids of every kind (digits, unicode, spaces), elements of both categories,
    0/1 topology for a ground truth (NaN scores), confidences in [0, 1] for a prediction."""
    names = ("7", "lane é", "0042", "l-3", "💡", "x y")
    lane_ids = tuple(
        f"{names[i % len(names)]}#{i}" if i >= len(names) else names[i] for i in range(lanes)
    )
    points = tuple(rng.normal(0, 20, (int(rng.integers(2, 7)), 3)) for _ in range(lanes))

    def scores(count: int) -> np.ndarray:
        return rng.uniform(0, 1, count) if predicted else np.full(count, np.nan)

    def links(rows: int, columns: int) -> np.ndarray:
        found = rng.uniform(0, 1, (rows, columns))
        return found if predicted else (found > 0.6).astype(np.float64)

    corners = rng.uniform(0, 1000, (elements, 2))
    return LaneGraph(
        lane_ids=lane_ids,
        lanes=points,
        lane_scores=scores(lanes),
        element_ids=tuple(str(100 + i) for i in range(elements)),
        element_boxes=np.hstack([corners, corners + rng.uniform(5, 80, (elements, 2))]),
        element_category=rng.integers(1, 3, elements),
        element_attribute=rng.integers(0, 13, elements),
        element_scores=scores(elements),
        lane_lane=links(lanes, lanes),
        lane_element=links(lanes, elements),
    )


def objects_3d(rng: np.random.Generator, ids: tuple[str, ...]) -> Objects3D:
    """3-D objects for ``ids``: unknown (NaN) velocity components and scores on some rows,
    labels of every kind (unicode and empty included), yaw over the whole circle."""
    n = len(ids)
    velocity = rng.normal(0, 8, (n, 3))
    velocity[::3, 2] = np.nan
    velocity[1::4] = np.nan
    score = rng.uniform(0, 1, n)
    score[2::5] = np.nan
    labels = ("CAR", "PEDESTRIAN", "", 'vélo "x"', "BUS")
    return Objects3D(
        ids=ids,
        location=rng.normal(0, 60, (n, 3)),
        yaw=rng.uniform(-180.0, 180.0, n),
        extent=rng.uniform(0.2, 3.0, (n, 3)),
        velocity=velocity,
        score=score,
        labels=tuple(labels[i % len(labels)] for i in range(n)),
    )


def add_3d(log: RunLog, seed: int = 0) -> RunLog:
    """``log`` with 3-D detections, tracks and control commands added (in place; returned),
    from a generator of its own so the other folders are unchanged.

    Detections (ids ``d<row>``) on every analysed frame but every sixth, one frame with none
    at all (an empty record); tracks (ids of the actors, uuid-like hex for some) on every
    other frame; a command on every frame but the third, with unknown (NaN) values on some;
    and one control command at a records-only stamp (none of the other folders has it)."""
    rng = np.random.default_rng(10_000 + seed)
    for f, ts in enumerate(dict.fromkeys(log.frames)):
        actors = log.actors.get(ts)
        ids = actors.ids if actors is not None else ()
        if f % 6 != 5:
            count = 0 if f == 2 else int(rng.integers(1, 9))
            log.detections_3d[ts] = objects_3d(rng, tuple(f"d{row}" for row in range(count)))
        if f % 2 == 0:
            track_ids = tuple(
                i if k % 2 else f"{zlib.crc32(i.encode()):08x}" * 4 for k, i in enumerate(ids)
            )
            log.tracks_3d[ts] = objects_3d(rng, track_ids)
        if f % 3 != 2:
            steer, acceleration, speed = rng.normal(0, 5, 3).tolist()
            if f % 5 == 4:
                acceleration = float("nan")
            log.controls[ts] = ControlCommand(steer=steer, acceleration=acceleration, speed=speed)
    if log.frames:
        log.controls[log.frames[-1] + 7] = ControlCommand(-0.0, float("nan"), 1e-300)
    add_lanes(log, seed)
    return log


def add_lanes(log: RunLog, seed: int = 0) -> RunLog:
    """``log`` with lane graphs added (in place; returned), from a generator of its own: a
    ground truth on every frame but every fourth (the second frame's empty, the third's
    without elements), a prediction on every third frame (the first without lanes)."""
    rng = np.random.default_rng(20_000 + seed)
    for f, ts in enumerate(dict.fromkeys(log.frames)):
        if f % 4 != 3:
            lanes = 0 if f == 1 else int(rng.integers(1, 7))
            elements = 0 if f in (1, 2) else int(rng.integers(1, 4))
            log.lanes[ts] = lane_graph(rng, lanes, elements, predicted=False)
        if f % 3 == 0:
            lanes = 0 if f == 0 else int(rng.integers(1, 5))
            log.lanes_predicted[ts] = lane_graph(rng, lanes, int(rng.integers(0, 3)), True)
    return log


def awkward_log() -> RunLog:
    """NaN everywhere, empty records, odd keys, negative and huge stamps, JSON extremes."""
    meta = RunMetadata(TPF, (0.0, 0.0, 0.0), -1, 4, raw={"timesteps_per_frame": TPF})
    log = RunLog(metadata=meta, frames=(-50, 0, 0, 2_000_000_050))
    nan = float("nan")
    log.pose[-50] = EgoPose(nan, -0.0, 0.0, nan, 0.0, 0.0, nan)
    log.pose[0] = EgoPose(1e308, 0.0, -1e-308, 179.0, 95.0, -400.0, 0.0)
    log.actors[-50] = Actors((), np.empty((0, 3)), np.empty((0, 3)), np.empty((0, 3)))
    log.actors[0] = Actors(
        ("é", "0", "2147483648", "ユニコード", "a" * 7),
        np.array([[nan, 0.0, -0.0]] * 5),
        np.array([[0.0, nan, 0.0]] * 5),
        np.array([[nan, -nan, 1.0]] * 5),
    )
    log.actors[2_000_000_050] = log.actors[0]
    log.bboxes[0] = Boxes(
        ("1", "ü"),
        np.array([[nan, 1.0, -0.0, 3.0], [1e-300, 2.0, 3.0, 4.0]]),
        ({"score": float("inf"), "n": 2**70}, {"nested": {"a": [1, nan]}, "id2": "x"}),
    )
    log.bboxes_gt[0] = Boxes((), np.empty((0, 4)), ())
    log.predictions[0] = {}
    log.predictions_with_perception[0] = {
        "ü": Track(("x", "01", "2"), np.array([[nan, -nan, 0.0], [1.0, 0.0, -0.0], [2, 3, 4.0]])),
        "empty": Track((), np.empty((0, 3))),
    }
    log.waypoints[0] = Plan(("0", "01", "x", "-3", "5"), np.full((5, 2), nan), np.full(5, nan))
    log.waypoints[-50] = Plan((), np.empty((0, 2)), np.empty(0))
    log.waypoints[2_000_000_050] = Plan(("01",), np.zeros((1, 2)), np.zeros(1))
    inf = float("inf")
    log.detections_3d[0] = Objects3D(
        ("é", "", "ユニコード", "0" * 40),
        np.array([[nan, -0.0, 1e308], [1e-300, 0.0, -5.0], [2.0, 3.0, 4.0], [0.0, 0.0, 0.0]]),
        np.array([nan, -0.0, 540.0, -180.0]),
        np.array([[nan, 1.0, 0.5], [0.0, 0.0, 0.0], [1e-320, 2.0, 3.0], [1.0, 1.0, 1.0]]),
        np.array([[inf, -inf, nan], [nan, nan, nan], [-0.0, 0.0, 1.5], [1.0, 2.0, 3.0]]),
        np.array([nan, inf, -0.0, 2.5]),
        ("", "\u202e", 'q"uote', "\\"),
    )
    log.tracks_3d[-50] = Objects3D(
        (), np.empty((0, 3)), np.empty(0), np.empty((0, 3)), np.empty((0, 3)), np.empty(0), ()
    )
    log.controls[0] = ControlCommand(nan, -inf, -0.0)
    log.controls[2_000_000_050] = ControlCommand(1e-300, 0.0, 1e308)
    # Points travel as float64 (NaN signs kept); scores, boxes and adjacency as JSON text
    # (NaN and infinities by the strict-JSON convention, so no -NaN there).
    log.lanes[0] = LaneGraph(
        lane_ids=("é", "0", "ユニコード"),
        lanes=(
            np.array([[nan, -0.0, 1e308], [1e-300, -nan, -5.0]]),
            np.empty((0, 3)),
            np.array([[1.0, 2.0, 3.0]]),
        ),
        lane_scores=np.array([nan, inf, -0.0]),
        element_ids=("\u202e", 'q"uote'),
        element_boxes=np.array([[nan, 1.0, -0.0, 3.0], [1e-320, 2.0, 3.0, -inf]]),
        element_category=np.array([1, 7]),
        element_attribute=np.array([0, -99]),
        element_scores=np.array([nan, 0.5]),
        lane_lane=np.array([[nan, inf, 0.0], [-0.0, 1.0, 0.5], [0.0, 0.0, 1e-310]]),
        lane_element=np.array([[1.0, 0.0], [nan, -inf], [0.25, 0.75]]),
    )
    log.lanes_predicted[-50] = LaneGraph.empty()
    log.lanes_predicted[2_000_000_050] = log.lanes[0]
    return log


def play_through_assembler(log: RunLog, *, serialise: bool = False) -> RunLogAssembler:
    """Everything the player would send for ``log``, fed to an assembler (optionally CDR)."""
    assembler = RunLogAssembler()

    def send(key: str, msg: object) -> None:
        if serialise:
            from rclpy.serialization import deserialize_message, serialize_message

            msg = deserialize_message(serialize_message(msg), topics.message_types()[key])
        assembler.add(key, msg)

    send(topics.METADATA, playback.metadata_message(log))
    ticks = playback.timeline(log)
    send(topics.STATUS, playback.status_message(playback.PLAYING, 0))
    for tick in ticks:
        send(topics.CLOCK, convert.clock_message(tick.stamp_ms))
        messages = topics.frame_messages(log, tick.stamp_ms)
        for key, msg in messages.items():
            send(key, msg)
        send(topics.FRAME, playback.frame_marker(tick, playback.published_names(messages), 50))
    send(topics.STATUS, playback.status_message(playback.FINISHED, len(ticks)))
    return assembler
