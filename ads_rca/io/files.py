"""Reading one input file safely: regular files only, never more than a size cap.

A log folder is untrusted. A FIFO named ``pose-3400.json`` blocks ``open``/``read``
forever; a symlink to ``/dev/zero`` or ``/dev/urandom`` reads until memory runs out; a huge
file exhausts memory in the JSON parser. So a file is read only when it is a regular file
(symlinks are followed, but their target must be a regular file), checked with ``stat``
before opening, opened non-blocking (a FIFO swapped in after the check cannot block) and
checked again with ``fstat`` on the opened descriptor; at most ``max_bytes + 1`` bytes are
ever read. Anything else is an :class:`Unreadable` naming why, for the caller's Problem.
"""

from __future__ import annotations

import os
import stat
from dataclasses import dataclass

#: Default cap of one record file (``max_file_mb``): the largest seed-format record files
#: (thousands of boxes) are a few MB, so this is generous and still bounds memory.
DEFAULT_MAX_FILE_MB = 64.0

_KINDS = (
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISFIFO, "FIFO"),
    (stat.S_ISCHR, "character device"),
    (stat.S_ISBLK, "block device"),
    (stat.S_ISSOCK, "socket"),
)
_OPEN_FLAGS = os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY | os.O_CLOEXEC
_READ_STEP = 1 << 16


@dataclass(frozen=True, slots=True)
class Unreadable:
    """Why a file was not read (the ``issue`` of the Problem the caller reports)."""

    issue: str


def max_bytes(max_file_mb: float) -> int:
    """The byte cap of ``max_file_mb`` megabytes (MB = 2**20 bytes)."""
    return int(max_file_mb * (1 << 20))


def read_regular(path: str | os.PathLike[str], limit: int) -> bytes | Unreadable:
    """The bytes of ``path`` if it is a regular file of at most ``limit`` bytes."""
    try:
        refused = _refuse(os.stat(path), limit)
        if refused is not None:
            return refused
        fd = os.open(path, _OPEN_FLAGS)
    except OSError as error:
        return Unreadable(f"cannot read: {error.strerror}")
    try:
        info = os.fstat(fd)
        refused = _refuse(info, limit)
        if refused is not None:  # replaced between stat and open
            return refused
        data = _read_at_most(fd, info.st_size, limit)
    except OSError as error:
        return Unreadable(f"cannot read: {error.strerror}")
    finally:
        os.close(fd)
    if len(data) > limit:  # grew after fstat
        return _too_large(limit)
    return data


def file_kind(mode: int) -> str:
    """``FIFO``, ``character device``... for a non-regular ``st_mode``."""
    return next((name for test, name in _KINDS if test(mode)), "not a file")


def _refuse(info: os.stat_result, limit: int) -> Unreadable | None:
    if not stat.S_ISREG(info.st_mode):
        return Unreadable(f"not a regular file ({file_kind(info.st_mode)})")
    if info.st_size > limit:
        return _too_large(limit)
    return None


def _too_large(limit: int) -> Unreadable:
    return Unreadable(f"larger than {limit / (1 << 20):g} MB (max_file_mb)")


def _read_at_most(fd: int, size_hint: int, limit: int) -> bytes:
    """Up to ``limit + 1`` bytes: the stated size in one read, then until end of file."""
    parts: list[bytes] = []
    total = 0
    while total <= limit:
        want = min(max(size_hint + 1 - total, _READ_STEP), limit + 1 - total)
        chunk = os.read(fd, want)
        if not chunk:
            break
        parts.append(chunk)
        total += len(chunk)
    return b"".join(parts)
