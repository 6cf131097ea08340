"""Reading one input file safely: regular files only, never more than a size cap.

A log folder is untrusted. A FIFO named ``pose-3400.json`` blocks ``open``/``read``
forever; a symlink to ``/dev/zero`` or ``/dev/urandom`` reads until memory runs out; a huge
file exhausts memory in the JSON parser. So a file is read only when it is a regular file
(symlinks are followed, but their target must be a regular file), checked with ``stat``
before opening, opened non-blocking (a FIFO swapped in after the check cannot block) and
checked again with ``fstat`` on the opened descriptor; at most ``max_bytes + 1`` bytes are
ever read. Anything else is an :class:`Unreadable` naming why, for the caller's Problem.

:func:`open_regular` applies the same checks to a file read as a stream (a bag's storage
file: large, read record by record, so no cap unless one is given).
"""

from __future__ import annotations

import errno
import os
import stat
from dataclasses import dataclass
from typing import BinaryIO

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


def read_regular(
    path: str | os.PathLike[str], limit: int, listed_regular: bool = False
) -> bytes | Unreadable:
    """The bytes of ``path`` if it is a regular file of at most ``limit`` bytes.

    ``listed_regular``: its directory listing said a regular file, no symlink (the entry's
    type, which costs no system call): then it is opened at once, with ``O_NOFOLLOW``, and
    checked with ``fstat`` alone. Only root can put a device node in its place; a symlink
    put there since is not followed but sent through the full check (``stat`` first), as a
    file not listed so is."""
    opened = _open_listed(path, limit) if listed_regular else _open_checked(path, limit)
    if isinstance(opened, Unreadable):
        return opened
    fd, size = opened
    try:
        data = _read_at_most(fd, size, limit)
    except OSError as error:
        return Unreadable(f"cannot read: {error.strerror}")
    finally:
        os.close(fd)
    if len(data) > limit:  # grew after fstat
        return _too_large(limit)
    return data


def open_regular(path: str | os.PathLike[str], limit: int | None = None) -> BinaryIO | Unreadable:
    """``path`` opened for binary reading if it is a regular file (of at most ``limit``
    bytes when given); the caller closes it. The descriptor is the one checked, so a file
    swapped for a FIFO after the check is never read."""
    opened = _open_checked(path, limit)
    if isinstance(opened, Unreadable):
        return opened
    fd, _size = opened
    return os.fdopen(fd, "rb")


def _open_checked(path: str | os.PathLike[str], limit: int | None) -> tuple[int, int] | Unreadable:
    """A descriptor of ``path`` and its size, checked before opening and after (fstat)."""
    try:
        refused = _refuse(os.stat(path), limit)
        if refused is not None:
            return refused
        fd = os.open(path, _OPEN_FLAGS)
    except OSError as error:
        return Unreadable(f"cannot read: {error.strerror}")
    return _checked_descriptor(fd, limit)


def _open_listed(path: str | os.PathLike[str], limit: int | None) -> tuple[int, int] | Unreadable:
    """:func:`_open_checked` for a file listed as regular: no ``stat`` before opening."""
    try:
        fd = os.open(path, _OPEN_FLAGS | os.O_NOFOLLOW)
    except OSError as error:
        if error.errno in (errno.ELOOP, errno.EMLINK):  # a symlink now (Linux, BSD): the
            # full check follows it
            return _open_checked(path, limit)
        return Unreadable(f"cannot read: {error.strerror}")
    return _checked_descriptor(fd, limit)


def _checked_descriptor(fd: int, limit: int | None) -> tuple[int, int] | Unreadable:
    """``fd`` and its size if ``fstat`` says a regular file within ``limit`` (else closed)."""
    try:
        info = os.fstat(fd)
    except OSError as error:
        os.close(fd)
        return Unreadable(f"cannot read: {error.strerror}")
    refused = _refuse(info, limit)
    if refused is not None:  # replaced between stat and open
        os.close(fd)
        return refused
    return fd, info.st_size


def file_kind(mode: int) -> str:
    """``FIFO``, ``character device``... for a non-regular ``st_mode``."""
    return next((name for test, name in _KINDS if test(mode)), "not a file")


def _refuse(info: os.stat_result, limit: int | None) -> Unreadable | None:
    if not stat.S_ISREG(info.st_mode):
        return Unreadable(f"not a regular file ({file_kind(info.st_mode)})")
    if limit is not None and info.st_size > limit:
        return _too_large(limit)
    return None


def _too_large(limit: int) -> Unreadable:
    return Unreadable(f"larger than {limit / (1 << 20):g} MB (max_file_mb)")


def _read_at_most(fd: int, size_hint: int, limit: int) -> bytes:
    """Up to ``limit + 1`` bytes: the stated size in one read, then until end of file (a
    short read is not taken for the end: on FUSE or NFS a signal can cut a read short).

    A first read that gives exactly the size ``fstat`` stated, fewer bytes than asked, is
    the whole file without asking again (one system call a file, not two: a log is
    thousands of small files): had it grown since, the read would have given more; cut
    short by a signal at exactly that size, it is the file as ``fstat`` saw it."""
    parts: list[bytes] = []
    total = 0
    while total <= limit:
        want = min(max(size_hint + 1 - total, _READ_STEP), limit + 1 - total)
        chunk = os.read(fd, want)
        if not chunk:
            break
        if not parts and len(chunk) == size_hint < want:
            return chunk
        parts.append(chunk)
        total += len(chunk)
    return b"".join(parts)
