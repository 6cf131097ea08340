"""A real full disk for a test: a small tmpfs mounted on a folder of the test's own.

A write past its size fails with ``ENOSPC`` in the kernel, as on a full disk: the rename,
the fsync and every partial write behave as they would there (a symlink to ``/dev/full``
fails every write too, but is a device: it has no folder to rename in). Mounting needs
root (or ``CAP_SYS_ADMIN``); where it is not permitted the test is skipped, saying why.
"""

from __future__ import annotations

import os
import subprocess
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest


@contextmanager
def small_tmpfs(folder: Path, size: str) -> Iterator[Path]:
    """``folder`` (created) with a tmpfs of ``size`` (``64k``, ``1m``) mounted on it while
    the block runs; unmounted after, whatever happens."""
    folder.mkdir(parents=True, exist_ok=True)
    mounted = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", f"size={size},mode=0777", "tmpfs", str(folder)],
        capture_output=True,
        text=True,
        check=False,
    )
    if mounted.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {mounted.stderr.strip() or mounted.returncode}")
    try:
        yield folder
    finally:
        if subprocess.run(["umount", str(folder)], check=False).returncode != 0:
            subprocess.run(["umount", "-l", str(folder)], check=False)


def fill(folder: Path) -> None:
    """Fill the file system of ``folder`` to its last byte (a file ``filler`` in it)."""
    with (folder / "filler").open("wb", buffering=0) as out:
        block = b"\0" * 4096
        try:
            while True:
                out.write(block)
        except OSError as error:
            assert error.errno == 28, error  # ENOSPC
    # A last partial block: write byte by byte until nothing fits.
    with (folder / "filler").open("ab", buffering=0) as out:
        try:
            while True:
                out.write(b"\0")
        except OSError:
            pass
    assert os.statvfs(folder).f_bavail == 0
