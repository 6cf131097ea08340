"""Reading one input file (``ads_rca/foundation/files.py``): regular files only, never more than the
cap, the whole file whatever ``fstat`` said; a file read in one system call when its size
is what ``fstat`` stated."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import pytest

from ads_rca.foundation import files
from ads_rca.foundation.files import Unreadable, read_regular


@pytest.fixture
def reads(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """The sizes asked of each ``os.read`` the module makes (the real call is made)."""
    asked: list[int] = []
    real = os.read

    def counted(fd: int, size: int) -> bytes:
        asked.append(size)
        return real(fd, size)

    monkeypatch.setattr("ads_rca.foundation.files.os.read", counted)
    return asked


@pytest.mark.parametrize("size", [0, 1, 18_249, 65_535, 65_536, 200_001])
def test_a_regular_file_comes_whole(tmp_path: Path, size: int, reads: list[int]) -> None:
    data = os.urandom(size)
    path = tmp_path / "f.json"
    path.write_bytes(data)
    assert read_regular(path, 1 << 20) == data
    assert len(reads) == 1  # its size as fstat stated it: no second read for the end


def test_the_cap_is_kept(tmp_path: Path) -> None:
    path = tmp_path / "f.json"
    path.write_bytes(b"x" * 100)
    assert read_regular(path, 100) == b"x" * 100
    refused = read_regular(path, 99)
    assert isinstance(refused, Unreadable) and "max_file_mb" in refused.issue


@pytest.mark.parametrize("hint", [0, 50, 99, 101, 200, 70_000])
def test_a_size_hint_gone_stale_still_reads_the_whole_file(tmp_path: Path, hint: int) -> None:
    """A file that grew or shrank after ``fstat``: read to its end, never taken as ended
    at the stale size."""
    data = os.urandom(100)
    path = tmp_path / "f.json"
    path.write_bytes(data)
    fd = os.open(path, os.O_RDONLY)
    try:
        assert files._read_at_most(fd, hint, 1 << 20) == data
    finally:
        os.close(fd)


def test_a_file_grown_past_the_cap_after_fstat_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "f.json"
    path.write_bytes(b"y" * 300)
    fd = os.open(path, os.O_RDONLY)
    try:  # fstat said 10 bytes, the cap is 200: at most 201 are read, then refused
        assert len(files._read_at_most(fd, 10, 200)) == 201
    finally:
        os.close(fd)


def test_what_is_not_a_regular_file_is_never_read(tmp_path: Path) -> None:
    fifo = tmp_path / "pose-100.json"
    os.mkfifo(fifo)
    link = tmp_path / "pose-200.json"
    link.symlink_to("/dev/zero")
    for path, kind in ((fifo, "FIFO"), (link, "character device"), (tmp_path, "a directory")):
        got = read_regular(path, 1 << 20)
        assert isinstance(got, Unreadable) and kind in got.issue, (path, got)
    missing = read_regular(tmp_path / "missing.json", 1 << 20)
    assert isinstance(missing, Unreadable) and "cannot read" in missing.issue


def test_a_file_listed_regular_is_opened_without_stat_and_a_symlink_there_is_checked(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Listed as a regular file: no ``stat`` before opening. A symlink found there instead
    (swapped in after the listing) is not followed by that open: it goes through the full
    check, so its target is read when regular and refused when a device."""
    stats: list[object] = []
    real_stat = os.stat

    def counted(path: Any) -> os.stat_result:
        stats.append(path)
        return real_stat(path)

    monkeypatch.setattr("ads_rca.foundation.files.os.stat", counted)
    plain = tmp_path / "pose-1.json"
    plain.write_bytes(b"{}")
    assert read_regular(plain, 100, listed_regular=True) == b"{}" and stats == []
    link = tmp_path / "pose-2.json"
    link.symlink_to(plain)
    assert read_regular(link, 100, listed_regular=True) == b"{}" and stats == [link]
    device = tmp_path / "pose-3.json"
    device.symlink_to("/dev/zero")
    got = read_regular(device, 100, listed_regular=True)
    assert isinstance(got, Unreadable) and "character device" in got.issue


def test_a_log_folder_lists_its_irregular_entries_for_the_full_check(tmp_path: Path) -> None:
    from ads_rca.problems import ProblemLog
    from ads_rca.sources.log.reader import _list_folder

    folder = tmp_path / "pose"
    folder.mkdir()
    (folder / "pose-100.json").write_bytes(b"{}")
    (folder / "pose-200.json").symlink_to(folder / "pose-100.json")
    os.mkfifo(folder / "pose-300.json")
    (folder / "pose-400.json").mkdir()
    irregular: set[str] = set()
    listing = _list_folder(tmp_path, "pose", ProblemLog(), irregular)
    assert sorted(listing) == [
        (100, "pose-100.json"),
        (200, "pose-200.json"),
        (300, "pose-300.json"),
        (400, "pose-400.json"),
    ]
    assert irregular == {"pose/pose-200.json", "pose/pose-300.json", "pose/pose-400.json"}
