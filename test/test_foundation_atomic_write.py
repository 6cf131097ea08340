"""``foundation.atomic_write``: a file replaced whole or not at all, on a real full disk.

A small tmpfs (``fulldisk.small_tmpfs``) gives the kernel's own ``ENOSPC``. Checked: a
write that does not fit raises ``OSError`` and leaves the old file byte for byte, with no
temporary file left behind; a write that fits replaces it, keeping its permission bits; a
symlink named as the output keeps pointing at its target, which is replaced; a name that is
no regular file (``/dev/null``, a FIFO with a reader) is written in place.
"""

from __future__ import annotations

import errno
import os
import stat
import threading
from pathlib import Path

import pytest
from fulldisk import fill, small_tmpfs

from ads_rca.foundation.atomic_write import replace_bytes, replace_text, replacing_text


def test_a_full_disk_leaves_the_old_file_whole(tmp_path: Path) -> None:
    with small_tmpfs(tmp_path / "disk", "64k") as disk:
        target = disk / "verdict.json"
        target.write_text("previous\n")
        fill(disk)
        with pytest.raises(OSError) as raised:
            replace_bytes(target, b"x" * 100_000)
        assert raised.value.errno == errno.ENOSPC
        with pytest.raises(OSError), replacing_text(disk / "new.json") as out:  # streamed
            for _ in range(1000):
                out.write("y" * 1000)
        assert target.read_text() == "previous\n"
        assert sorted(p.name for p in disk.iterdir()) == ["filler", "verdict.json"]
        (disk / "filler").unlink()
        replace_text(target, "new\n")
        assert target.read_text() == "new\n"


def test_the_mode_and_a_symlink_are_kept(tmp_path: Path) -> None:
    target = tmp_path / "real" / "profile.yaml"
    target.parent.mkdir()
    target.write_text("old")
    target.chmod(0o640)
    link = tmp_path / "link.yaml"
    link.symlink_to(target)
    replace_text(link, "new")
    assert link.is_symlink() and target.read_text() == "new"
    assert stat.S_IMODE(target.stat().st_mode) == 0o640
    fresh = tmp_path / "missing" / "folder" / "out.json"  # parents made
    replace_bytes(fresh, b"{}")
    assert fresh.read_bytes() == b"{}"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link.yaml", "missing", "real"]


def test_a_name_that_is_no_regular_file_is_written_in_place(tmp_path: Path) -> None:
    replace_text(os.devnull, "into the void")  # /dev/null stays the device
    assert stat.S_ISCHR(os.stat(os.devnull).st_mode)
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    got: list[bytes] = []
    reader = threading.Thread(target=lambda: got.append(fifo.read_bytes()))
    reader.start()
    replace_bytes(fifo, b"through the pipe")
    reader.join(10)
    assert got == [b"through the pipe"]
    assert stat.S_ISFIFO(fifo.lstat().st_mode)
    with pytest.raises(OSError) as raised:
        replace_bytes("/dev/full", b"x")
    assert raised.value.errno == errno.ENOSPC
