"""Writing a file the user named: whole or not at all, its earlier content kept on failure.

A write straight into the file (``open(path, "w")``) truncates it first: a disk that fills
half-way (``ENOSPC``), or any other error, leaves neither the old content nor the new. Here
the new content goes to a temporary file in the same folder (so the rename never crosses a
file system), is flushed and ``fsync``-ed, then renamed over the name (``os.replace``, atomic
on POSIX), and the folder is ``fsync``-ed so that the rename survives a power cut. On any
failure the temporary file is removed, the name is left as it was (its old content, or no
file), and the caller gets the ``OSError``.

- Missing parent folders are created (every writer did so before).
- The temporary file (``.NAME.RANDOM.tmp``) is created ``O_EXCL | O_NOFOLLOW`` with mode
  0666, the umask applying as to a plain ``open``; an existing file's permission bits (and,
  for root, its owner) are copied to it: replacing a file changes its content only.
- A symlink named as the output is followed: its target is replaced, the link kept.
- A name that is no regular file (``/dev/stdout``, a FIFO, ``/dev/null``) cannot be
  replaced: it is written in place, as before (there is no earlier content to keep).
- Hard links to the old file keep the old content (the name gets a new inode).
- A process killed mid-write (SIGKILL, a power cut) leaves its temporary file beside the
  output, never a cut output.
"""

from __future__ import annotations

import contextlib
import os
import stat
from collections.abc import Iterator
from contextlib import contextmanager
from typing import IO, Any, BinaryIO, TextIO, cast

_CREATE = os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC
#: Characters of the output's name kept in the temporary file's (a name of 255 UTF-8
#: bytes plus the random part would be too long).
_NAME_CHARS = 40


def replace_bytes(path: str | os.PathLike[str], data: bytes) -> None:
    """``path`` replaced by ``data`` (see the module docstring)."""
    with replacing_binary(path) as out:
        out.write(data)


def replace_text(
    path: str | os.PathLike[str], text: str, encoding: str = "utf-8", errors: str = "strict"
) -> None:
    """``path`` replaced by ``text`` (see the module docstring)."""
    with replacing_text(path, encoding, errors) as out:
        out.write(text)


@contextmanager
def replacing_binary(path: str | os.PathLike[str], buffering: int = -1) -> Iterator[BinaryIO]:
    """A binary file whose content replaces ``path`` once the block ends without an
    exception; on any exception ``path`` is left as it was."""
    with _replacing(path, "wb", buffering, None, None) as out:
        yield cast(BinaryIO, out)


@contextmanager
def replacing_text(
    path: str | os.PathLike[str],
    encoding: str = "utf-8",
    errors: str = "strict",
    buffering: int = -1,
) -> Iterator[TextIO]:
    """:func:`replacing_binary` for text (``encoding``, ``errors`` as ``open``'s)."""
    with _replacing(path, "w", buffering, encoding, errors) as out:
        yield cast(TextIO, out)


@contextmanager
def _replacing(
    path: str | os.PathLike[str],
    mode: str,
    buffering: int,
    encoding: str | None,
    errors: str | None,
) -> Iterator[IO[Any]]:
    target = os.fspath(path)
    try:
        info: os.stat_result | None = os.stat(target)
    except FileNotFoundError:
        info = None
    if info is not None and not stat.S_ISREG(info.st_mode):
        with open(target, mode, buffering, encoding, errors) as out:
            yield out
        return
    if os.path.islink(target):
        target = os.path.realpath(target)
    folder = os.path.dirname(target) or "."
    os.makedirs(folder, exist_ok=True)
    fd, temporary = _create_temporary(folder, os.path.basename(target))
    try:
        if info is not None:
            _copy_owner_and_mode(fd, info)
        with open(fd, mode, buffering, encoding, errors) as out:
            yield out
            out.flush()
            os.fsync(out.fileno())
        os.replace(temporary, target)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(temporary)
        raise
    _fsync_folder(folder)


def _create_temporary(folder: str, name: str) -> tuple[int, str]:
    """A new file beside the output, opened for writing: its descriptor and path."""
    for _ in range(100):
        temporary = os.path.join(folder, f".{name[:_NAME_CHARS]}.{os.urandom(6).hex()}.tmp")
        try:
            return os.open(temporary, _CREATE, 0o666), temporary
        except FileExistsError:
            continue
    raise FileExistsError(f"no free temporary name in {folder}")


def _copy_owner_and_mode(fd: int, info: os.stat_result) -> None:
    if os.geteuid() == 0:  # only root can give a file away; the owner first (chown clears
        # the set-id bits that chmod then sets)
        with contextlib.suppress(OSError):
            os.fchown(fd, info.st_uid, info.st_gid)
    os.fchmod(fd, stat.S_IMODE(info.st_mode))


def _fsync_folder(folder: str) -> None:
    """The rename made durable; a file system that cannot sync a folder is no error (the
    file's content is synced and in place)."""
    try:
        fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
