"""A reader process hands a large chunk's numbers over in a shared-memory file
(sources/packing.SharedNumbers) instead of the pipe message: the parent must rebuild exactly the
records the message would have given, and no file may stay behind (mapped, dropped unread,
or never written when the directory cannot take it)."""

from __future__ import annotations

import gc
import pickle
from collections.abc import Iterable
from pathlib import Path
from typing import TypeVar

import numpy as np
import pytest
from logcompare import assert_logs_equal

from ads_rca.model import ALL_FOLDERS, Actors, Record, RunLog
from ads_rca.sources.log import packing
from ads_rca.sources.log import reader as log_reader
from ads_rca.sources.log.packing import Packer, SharedNumbers, unpack
from ads_rca.sources.log.reader import read_run_log
from ads_rca.sources.log.writer import write_run_log
from ads_rca.synth import synthesise

T = TypeVar("T")


@pytest.fixture(scope="module")
def crash_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    frames = synthesise("cut_in", "prediction", seed=2, frames=200)
    return write_run_log(frames, tmp_path_factory.mktemp("shared") / "log")


def packer_of(log: RunLog) -> Packer:
    packer = Packer()
    for folder in ALL_FOLDERS:
        for ts, record in log.folder(folder).items():
            packer.add(folder, ts, record)
    return packer


def rebuilt(log: RunLog, records: list[tuple[str, int, Record]]) -> RunLog:
    by_folder = {f: {ts: r for g, ts, r in records if g == f} for f in ALL_FOLDERS}
    return RunLog.from_folders(log.metadata, log.frames, by_folder)


@pytest.fixture
def shared_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """Every chunk handed over in a file of a directory of the test's own."""
    directory = tmp_path / "shm"
    directory.mkdir()
    monkeypatch.setattr(packing, "SHARED_DIR", str(directory))
    monkeypatch.setattr(packing, "SHARED_MIN_BYTES", 0)
    monkeypatch.setattr(packing, "SHARED_FREE_SHARE", 0.0)  # whatever the disk holds
    return directory


def test_a_chunk_sent_through_a_file_rebuilds_the_records_of_the_message(
    crash_log: Path, shared_dir: Path
) -> None:
    log = read_run_log(crash_log)
    packer = packer_of(log)
    numbers, entries = packer.packed()
    handed = packer.handed()
    assert isinstance(handed[0], SharedNumbers) and handed[1] is entries
    [written] = shared_dir.iterdir()
    assert written.read_bytes() == numbers.tobytes()  # float64, row-major, end to end
    # As the pipe carries it: pickled in the reader, unpickled here.
    received = pickle.loads(pickle.dumps(handed))
    del handed
    gc.collect()
    assert list(shared_dir.iterdir()) == [written]  # the sender's copy leaves the file
    records = list(unpack(received))
    assert list(shared_dir.iterdir()) == []  # mapped, then removed
    assert_logs_equal(log, rebuilt(log, records), angle_tol=0.0)
    assert_logs_equal(log, rebuilt(log, list(unpack((numbers, entries)))), angle_tol=0.0)
    actors = next(r for f, _, r in records if f == "actors")
    assert isinstance(actors, Actors)
    assert actors.location.dtype == np.float64 and actors.location.flags.writeable


def test_a_received_chunk_never_rebuilt_removes_its_file(crash_log: Path, shared_dir: Path) -> None:
    handed = packer_of(read_run_log(crash_log)).handed()
    received = pickle.loads(pickle.dumps(handed))
    assert len(list(shared_dir.iterdir())) == 1
    del received
    gc.collect()
    assert list(shared_dir.iterdir()) == []


def test_small_chunks_and_an_unusable_directory_keep_the_numbers_in_the_message(
    crash_log: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    packer = packer_of(read_run_log(crash_log))
    numbers = packer.packed()[0]
    monkeypatch.setattr(packing, "SHARED_MIN_BYTES", numbers.nbytes + 1)
    assert isinstance(packer.handed()[0], np.ndarray)  # one byte short of the threshold
    monkeypatch.setattr(packing, "SHARED_MIN_BYTES", 0)
    monkeypatch.setattr(packing, "SHARED_DIR", str(tmp_path / "missing"))
    small = packer.handed()[0]
    assert isinstance(small, np.ndarray) and small.tobytes() == numbers.tobytes()


def test_a_log_read_in_workers_through_files_equals_one_read_here(
    crash_log: Path, shared_dir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The forked readers inherit the lowered threshold: every chunk goes through a file."""
    monkeypatch.setattr(log_reader, "PARALLEL_MIN_FILES", 1)
    alone, shared = read_run_log(crash_log), read_run_log(crash_log, workers=2)
    assert_logs_equal(alone, shared, angle_tol=0.0)
    assert list(alone.problems) == list(shared.problems)
    assert list(shared_dir.iterdir()) == []


def test_a_chunk_goes_to_shared_memory_only_while_half_of_it_stays_free(tmp_path: Path) -> None:
    """The loaded records keep their pages in that file system: a chunk taking every free
    byte and one more is never written, nor one leaving less than half of it free."""
    import os

    from ads_rca.sources.log.packing import _room_for

    if not os.path.isdir(packing.SHARED_DIR):
        pytest.skip(f"no {packing.SHARED_DIR} here")
    info = os.statvfs(packing.SHARED_DIR)
    assert info.f_blocks > 0
    assert not _room_for(info.f_bavail * info.f_frsize + 1)
    if 2 * info.f_bavail > info.f_blocks + 2:  # more than half free: a byte fits
        assert _room_for(1)


def test_an_interrupted_reading_leaves_no_file_behind(crash_log: Path, shared_dir: Path) -> None:
    """Ctrl-C after the first chunk: the workers have written other chunks' files that the
    parent never receives; the reading removes them (its own prefix) as it stops."""

    class Interrupted(Exception):
        pass

    def stop_after_first_chunk(items: Iterable[T]) -> Iterable[T]:
        for done, item in enumerate(items):
            if done:
                raise Interrupted
            yield item

    with pytest.raises(Interrupted):
        read_run_log(crash_log, workers=2, progress=stop_after_first_chunk)
    assert not list(shared_dir.iterdir())
    other = shared_dir / f"{packing.SHARED_PREFIX}99999-0-kept.f64"  # not this reading's
    other.write_bytes(b"")
    read_run_log(crash_log, workers=2)
    assert [p.name for p in shared_dir.iterdir()] == [other.name]
