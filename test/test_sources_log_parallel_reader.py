"""Reading a log in forked workers gives exactly the log and problems of reading it here.

``read_run_log(..., workers=N)`` parses interleaved chunks of the files (every n-th file) in
worker processes, rebuilds their records from packed arrays (``sources/log/packing.py``) and puts
the
problems back in file order. On hostile folders
(duplicated timestamps, corrupt and empty files, strings where numbers belong, a missing
folder, a FIFO, files without a timestamp, records dropped, nesting too deep, a file over the
size cap) the result must be the single-process one: the same records, arrays of the same
dtype and shape, the same problems in the same order, the same file names.
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from logcompare import assert_logs_equal
from logfactory import add_3d, make_log

from ads_rca.model import ALL_FOLDERS, RunLog, Track
from ads_rca.sources.log import reader as log_reader
from ads_rca.sources.log.packing import Packer, unpack
from ads_rca.sources.log.reader import read_run_log
from ads_rca.sources.log.writer import write_run_log
from ads_rca.synth import synthesise


@pytest.fixture(scope="module")
def crash_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_run_log(
        synthesise("cut_in", "perception", seed=1), tmp_path_factory.mktemp("p") / "log"
    )


def _edit(path: Path, change: Any) -> None:
    document = json.loads(path.read_text())
    change(document)
    path.write_text(json.dumps(document))


def _nth(folder: Path, index: int) -> Path:
    return sorted(p for p in folder.iterdir() if p.suffix == ".json")[index]


def damage(root: Path) -> None:
    """Every kind of bad input the reader reports, spread over the folders."""
    actors = _nth(root / "actors", 5)
    copy = actors.with_name(actors.name.replace("-", "-0", 1))
    shutil.copy(actors, copy)  # a duplicated timestamp (the last listed wins)
    _edit(copy, lambda d: d[next(iter(d))]["location"].update(x=123.0))
    pose = _nth(root / "pose", 7)
    shutil.copy(pose, pose.with_name(pose.name.replace("-", "-00", 1)))
    _nth(root / "pose", 9).write_text("{")  # corrupt
    _nth(root / "bboxes", 4).write_text("")  # empty
    _nth(root / "waypoint", 3).write_bytes(b"\xff\xfe not json")
    _edit(_nth(root / "pose", 12), lambda d: d.update(x="not a number", y="12.5"))
    _edit(
        _nth(root / "actors", 14),
        lambda d: d[next(iter(d))]["location"].update(y="7.25", z=[1]),
    )
    _edit(_nth(root / "bboxes_gt", 6), lambda d: d.append({"bounding_box": [[1, 2]]}))
    _edit(_nth(root / "predictions", 8), lambda d: d.update(x={"1": {"x": "a", "y": 2}}))
    _nth(root / "predictions_with_perception", 10).write_text("[1, 2]")  # wrong type
    _nth(root / "waypoint", 11).write_text('{"0": {"x": NaN, "y": 1, "speed": Infinity}}')
    _nth(root / "bboxes", 20).write_text("[" * 300 + "]" * 300)  # nested too deep
    (root / "actors" / "actors.json").write_text("{}")  # no timestamp
    (root / "pose" / ".hidden-50.json").write_text("{")  # ignored
    os.mkfifo(root / "bboxes_gt" / "bboxes_gt-99999.json")
    _nth(root / "predictions", 15).write_text(json.dumps({"big": "x" * 40_000}))  # too large


def _read_both(root: Path, monkeypatch: pytest.MonkeyPatch) -> tuple[RunLog, RunLog]:
    alone = read_run_log(root, max_file_mb=0.03)
    monkeypatch.setattr(log_reader, "PARALLEL_MIN_FILES", 1)
    monkeypatch.setattr(log_reader, "CHUNKS_PER_WORKER", 7)
    shared = read_run_log(root, max_file_mb=0.03, workers=3)
    return alone, shared


def _arrays(log: RunLog) -> list[np.ndarray]:
    found: list[np.ndarray] = []
    for folder in ALL_FOLDERS:
        for record in log.folder(folder).values():
            values = record.values() if isinstance(record, dict) else [record]
            for value in values:
                fields = (getattr(value, f.name) for f in dataclasses.fields(value))
                found += [v for v in fields if isinstance(v, np.ndarray)]
    return found


def assert_same_reading(alone: RunLog, shared: RunLog) -> None:
    assert list(shared.problems) == list(alone.problems)
    assert shared.files == alone.files
    assert (shared.source, shared.inputs) == (alone.source, alone.inputs)
    assert_logs_equal(alone, shared, angle_tol=0.0)
    for folder in ALL_FOLDERS:
        a, b = alone.folder(folder), shared.folder(folder)
        assert list(a) == list(b), folder  # the same timestamps in the same order
        assert [type(r) for r in a.values()] == [type(r) for r in b.values()], folder
    pairs = zip(_arrays(alone), _arrays(shared), strict=True)
    assert all(x.dtype == y.dtype and x.shape == y.shape for x, y in pairs)


def test_hostile_folder_reads_the_same_in_workers(
    crash_log: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    root = Path(shutil.copytree(crash_log, tmp_path / "log"))
    damage(root)
    alone, shared = _read_both(root, monkeypatch)
    issues = {p.issue.split(" (")[0] for p in alone.problems}
    assert {"empty file", "not a regular file"} <= issues
    assert any(p.issue.startswith("larger than") for p in alone.problems)
    assert any("also given by" in p.issue for p in alone.problems)
    assert len(alone.problems) > 15
    assert_same_reading(alone, shared)


def test_missing_folders_and_metadata_read_the_same_in_workers(
    crash_log: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    root = Path(shutil.copytree(crash_log, tmp_path / "log"))
    for folder in ("bboxes", "predictions"):
        shutil.rmtree(root / folder)
    (root / "metadata.json").write_text('{"collision_frame": "64", "timesteps_per_frame": 50}')
    alone, shared = _read_both(root, monkeypatch)
    assert any(p.issue == "folder missing" for p in alone.problems)
    assert_same_reading(alone, shared)


def test_3d_objects_and_control_commands_read_the_same_in_workers(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # 3-D objects travel as columns of the chunk's one array (not pickled one by one):
    # NaN velocities and scores, empty frames and each column's shape must come back.
    root = write_run_log(add_3d(make_log(14, 7, 2, orphan_stamps=True), 2), tmp_path / "log")
    alone, shared = _read_both(root, monkeypatch)
    objects = [*alone.detections_3d.values(), *alone.tracks_3d.values()]
    assert len(alone.detections_3d) > 5 and len(alone.tracks_3d) > 5 and alone.controls
    assert any(len(o) == 0 for o in objects) and any(len(o) > 1 for o in objects)
    assert any(np.isnan(o.velocity).any() or np.isnan(o.score).any() for o in objects)
    assert_same_reading(alone, shared)


def test_packed_records_rebuild_exactly(crash_log: Path) -> None:
    log = read_run_log(crash_log)
    packer = Packer()
    order = [(f, ts, r) for f in ALL_FOLDERS for ts, r in log.folder(f).items()]
    for folder, ts, record in order:
        packer.add(folder, ts, record)
    rebuilt = list(unpack(packer.packed()))
    assert [(f, ts) for f, ts, _ in rebuilt] == [(f, ts) for f, ts, _ in order]
    copy = RunLog.from_folders(
        log.metadata,
        log.frames,
        {f: {ts: r for g, ts, r in rebuilt if g == f} for f in ALL_FOLDERS},
    )
    assert_logs_equal(log, copy, angle_tol=0.0)


@pytest.mark.parametrize(
    "document",
    [
        {},  # no track
        {"7": {}},  # a track without steps
        {"7": {"0": {"x": 1, "y": 2, "z": 3}, "1": {"x": 1.5, "y": -2, "z": 0}}, "9": {}},
        {"3": {"5": {"x": 0.25, "y": 1e300, "z": -0.0}}, "4": {"5": {"x": 2, "y": 2, "z": 2}}},
    ],
)
def test_a_predictions_file_packed_in_pieces_is_packed_as_its_record(document: Any) -> None:
    """The readers pack a clean predictions file's pieces without making its tracks; what
    they send must be what packing the record parse_predictions makes sends: the same
    numbers (integers as floats) and the same entry."""
    from ads_rca.problems import ProblemLog
    from ads_rca.sources.log.records import parse_predictions, prediction_parts

    problems = ProblemLog()
    record = parse_predictions(document, "predictions/p-50.json", problems, 50)
    parts = prediction_parts(document)
    assert record is not None and parts is not None and not list(problems)
    whole, pieces = Packer(), Packer()
    whole.add("predictions", 50, record)
    pieces.add_predictions("predictions", 50, *parts)
    (numbers_a, entries_a), (numbers_b, entries_b) = whole.packed(), pieces.packed()
    assert numbers_a.dtype == numbers_b.dtype == np.float64
    assert numbers_a.tobytes() == numbers_b.tobytes()
    assert entries_a == entries_b


def test_the_collector_is_paused_while_reading_and_restored_after(tmp_path: Path) -> None:
    import gc

    from ads_rca.foundation.workers import collector_paused

    for enabled in (True, False):
        (gc.enable if enabled else gc.disable)()
        try:
            with collector_paused():
                assert not gc.isenabled()
            assert gc.isenabled() is enabled
            with pytest.raises(RuntimeError), collector_paused():
                raise RuntimeError
            assert gc.isenabled() is enabled
        finally:
            gc.enable()
    log = write_run_log(synthesise("cruise", "none", seed=0, frames=30), tmp_path / "log")
    assert read_run_log(log).frames and gc.isenabled()  # the reader gives it back


def test_what_a_paused_stretch_allocated_skips_the_young_collections() -> None:
    """After the pause, the 20,000 lists made during it are not waiting for a young
    collection (gen0's count starts again below its threshold, 700 by default) and are not
    left frozen outside a frozen block (inside one they join it); a cycle made during the
    pause is still freed by a full collection."""
    import gc

    from ads_rca.foundation.workers import collector_paused, loaded_objects_frozen

    class Node:
        pass

    gc.collect()
    with collector_paused():
        kept = [[i] for i in range(20_000)]
        cycle = Node()
        cycle.self = cycle  # type: ignore[attr-defined]
        del cycle
    assert gc.isenabled() and gc.get_freeze_count() == 0
    assert gc.get_count()[0] < gc.get_threshold()[0]
    assert gc.collect() >= 1  # the Node (and its __dict__)
    with loaded_objects_frozen():
        before = gc.get_freeze_count()
        with collector_paused():
            more = [[i] for i in range(20_000)]
        assert gc.get_freeze_count() >= before + len(more)
    assert gc.get_freeze_count() == 0 and len(kept) == 20_000


def _square(n: int) -> int:
    return n * n


def test_frozen_blocks_nest_and_only_the_outermost_unfreezes() -> None:
    """The diagnose command freezes the loaded run and the forked map freezes again inside:
    the inner block's end must not hand the run back to the collector."""
    import gc

    from ads_rca.foundation.workers import loaded_objects_frozen, map_forked

    assert gc.get_freeze_count() == 0
    loaded = [{"record": i} for i in range(1000)]
    with loaded_objects_frozen():
        frozen = gc.get_freeze_count()
        assert frozen >= len(loaded)
        with loaded_objects_frozen():
            pass
        assert gc.get_freeze_count() >= frozen
        assert list(map_forked(_square, range(5), 2)) == [0, 1, 4, 9, 16]
        assert gc.get_freeze_count() >= frozen
        with pytest.raises(RuntimeError), loaded_objects_frozen():
            raise RuntimeError
        assert gc.get_freeze_count() >= frozen
    assert gc.get_freeze_count() == 0


def test_tables_of_frames_sharing_one_ids_tuple_are_the_per_frame_ones(
    crash_log: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The workers' packer shares one ids tuple among the frames listing the same actors,
    and the reference tables and first extents are built once per group of equal tuples.
    Read here (a tuple a frame), with every equal tuple shared, and in workers, they must
    be the tables built a frame at a time. Actors leave and come back, no extent is known
    for the first five frames and extents change from frame to frame, so the frame an
    extent comes from shows."""
    from ads_rca.oracles.reference import oracles
    from ads_rca.oracles.reference.oracles import _build_tables

    def frame_by_frame() -> oracles._Tables:
        """The tables of ``alone`` with each frame a group of its own."""
        with monkeypatch.context() as patch:
            patch.setattr(
                oracles,
                "_frames_by_ids",
                lambda log, times: [(log.actors[t].ids, [u]) for u, t in enumerate(times)],
            )
            return _build_tables(alone)

    root = Path(shutil.copytree(crash_log, tmp_path / "log"))
    files = sorted((root / "actors").iterdir(), key=lambda f: int(f.stem.rpartition("-")[2]))
    leaving = next(iter(json.loads(files[0].read_text())))
    for index, file in enumerate(files):
        document = json.loads(file.read_text())
        if 10 <= index < 20:
            document.pop(leaving, None)  # gone for ten frames, then back
        for actor in document.values():
            actor["extent"]["x"] = "unknown" if index < 5 else 1.0 + index / 100
        file.write_text(json.dumps(document))
    alone, shared = _read_both(root, monkeypatch)
    assert list(shared.problems) == list(alone.problems)  # "missing where it first appears"
    assert sum("first appears" in p.issue for p in alone.problems) == len(alone.actor_extents)
    regrouped = read_run_log(root)
    tuples: dict[tuple[str, ...], tuple[str, ...]] = {}
    for ts, record in regrouped.actors.items():
        regrouped.actors[ts] = dataclasses.replace(
            record, ids=tuples.setdefault(record.ids, record.ids)
        )
    assert 2 <= len(tuples) < len(regrouped.actors) / 10
    expected = frame_by_frame()
    for log in (alone, shared, regrouped):
        assert list(alone.actor_extents) == list(log.actor_extents)
        for a, b in zip(alone.actor_extents.values(), log.actor_extents.values(), strict=True):
            assert np.array_equal(a, b)
        built = _build_tables(log)
        for field in dataclasses.fields(expected):
            a, b = getattr(expected, field.name), getattr(built, field.name)
            if isinstance(a, np.ndarray):
                assert a.dtype == b.dtype and np.array_equal(a, b, equal_nan=True), field.name
            else:
                assert a == b, field.name


def test_a_long_log_is_read_in_chunks_of_at_most_max_chunk_files() -> None:
    # 2 workers x 4 chunks = 8; 70,000 files / 2,000 = 35 chunks (each 2,000 files, the
    # last 0); 13,700 / 2,000 = 6.85 -> 7 < 8 keeps 8; 5 files make at most 5 chunks.
    assert (log_reader.CHUNKS_PER_WORKER, log_reader.MAX_CHUNK_FILES) == (4, 2000)
    assert log_reader.chunk_count(70_000, 2) == 35
    assert log_reader.chunk_count(70_001, 2) == 36
    assert log_reader.chunk_count(13_700, 2) == 8
    assert log_reader.chunk_count(5, 2) == 5


def test_a_log_in_many_small_chunks_reads_the_same_in_workers(
    crash_log: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    alone = read_run_log(crash_log)
    monkeypatch.setattr(log_reader, "PARALLEL_MIN_FILES", 1)
    monkeypatch.setattr(log_reader, "MAX_CHUNK_FILES", 3)
    assert log_reader.chunk_count(len(list(crash_log.glob("*/*.json"))), 2) > 8
    assert_same_reading(alone, read_run_log(crash_log, workers=2))


def _track_rows(track: Track) -> tuple[tuple[str, ...], list[list[float]], bool]:
    return track.keys, track.offsets.tolist(), track.offsets.flags.c_contiguous


@pytest.mark.parametrize(
    "keys",
    [
        [("0", "1"), ("0", "1"), ("0", "1")],  # every track the same steps: one 3-D view
        [("0", "1"), ("0",), (), ("2", "0", "1")],  # different steps: a slice each
        [(), ()],  # tracks without steps
    ],
)
def test_packed_tracks_rebuild_as_views_of_the_numbers(keys: list[tuple[str, ...]]) -> None:
    # Offsets numbered 0, 1, 2 ... through all tracks, so a track given the rows of another
    # shows as wrong values.
    rows = sum(map(len, keys))
    numbers = np.arange(3.0 * rows).reshape(-1, 3)
    ends = np.cumsum([0, *map(len, keys)])
    record = {f"id{i}": Track(k, numbers[ends[i] : ends[i + 1]].copy()) for i, k in enumerate(keys)}
    packer = Packer()
    packer.add("predictions", 50, record)
    packed = packer.packed()
    [(folder, ts, rebuilt)] = list(unpack(packed))
    assert (folder, ts) == ("predictions", 50)
    assert isinstance(rebuilt, dict) and list(rebuilt) == list(record)
    for obstacle_id, track in record.items():
        copy = rebuilt[obstacle_id]
        assert type(copy) is Track
        assert _track_rows(copy) == _track_rows(track)
        assert copy.offsets.shape == (len(track.keys), 3) and copy.offsets.dtype == np.float64
        assert copy.offsets.size == 0 or np.shares_memory(copy.offsets, packed[0])


def test_a_track_made_by_of_is_the_track_its_constructor_makes() -> None:
    offsets = np.array([[1.0, 2.0, 0.0], [3.0, 4.0, 0.5]])
    made, built = Track.of(("0", "x"), offsets), Track(("0", "x"), offsets)
    assert type(made) is Track
    assert made.keys == built.keys and made.offsets is built.offsets
    assert made.steps.tolist() == built.steps.tolist() == [0, -1]  # "x" is no step
    assert made.offset("x") is not None and made.offset("y") is None
    with pytest.raises(dataclasses.FrozenInstanceError):
        made.keys = ()  # type: ignore[misc]
