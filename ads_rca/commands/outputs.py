"""Output paths checked before the work starts: one line and exit status 2, not a traceback
after minutes of work.

Every command that writes (``--json``, ``--report``, ``convert``'s OUT, ``replay --record``,
``demo --out``) checks its paths here first. The writers create missing parent folders, so
a path is usable when its nearest existing ancestor is a directory we can create files in.
An output file replaces an existing one whole (:mod:`ads_rca.foundation.atomic_write`: a
temporary file beside it, renamed), so an existing regular file needs its folder writable
too; one that is no regular file (``/dev/stdout``, a FIFO) is written in place and must
open for writing. Both are tested for real (a probe file created and removed; an open
without truncation), not with ``os.access``: root passes every permission check, yet
cannot write in ``/proc`` or on a read-only mount.

A write that fails all the same once the work is done (a disk that filled meanwhile) is
:func:`unwritten`'s one line, exit status 2, as a path refused up front; the earlier file is
left whole.
"""

from __future__ import annotations

import os
from pathlib import Path

from ads_rca.errors import InputError


def check_output_file(path: str | os.PathLike[str], option: str) -> Path:
    """``path`` can be written as a file (``option`` names it in the error)."""
    target = Path(path)
    if target.is_dir():
        raise InputError(f"{option} {target}: is a directory (expected a file name)")
    if os.path.lexists(target):
        if os.path.exists(target) and not os.path.isfile(target):
            _probe_open(target, option)
        else:  # replaced by a rename in its (or its symlink's target's) folder
            _check_can_create_in(target, option, Path(os.path.realpath(target)))
        return target
    _check_can_create_in(target, option)
    return target


def unwritten(option: str, path: str | os.PathLike[str], error: OSError) -> InputError:
    """The one line of an output ``path`` (of ``option``) whose write failed with ``error``
    (a full disk): it was replaced whole or not at all, so it is left as it was."""
    why = error.strerror or str(error)
    return InputError(f"{option} {Path(path)}: cannot write ({why}); left as it was")


def check_output_dir(path: str | os.PathLike[str], option: str, empty: bool = True) -> Path:
    """``path`` can be created as a new folder, or is an (``empty``) one we can write in."""
    target = Path(path)
    if os.path.lexists(target):
        if not target.is_dir():
            raise InputError(f"{option} {target}: exists and is not a directory")
        if empty and any(target.iterdir()):
            raise InputError(f"{option} {target}: exists and is not an empty directory")
        _probe(target, target, option)
        return target
    _check_can_create_in(target, option)
    return target


def _check_can_create_in(target: Path, option: str, real: Path | None = None) -> None:
    """A file ``target`` (at ``real``, a symlink's target) can be created."""
    ancestor = (real or target).absolute().parent
    while not os.path.lexists(ancestor) and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise InputError(f"{option} {target}: {ancestor} is not a directory")
    _probe(ancestor, target, option)


def _probe_open(target: Path, option: str) -> None:
    """Open an existing ``target`` for writing without truncating it or writing anything
    (non-blocking: a FIFO nobody reads fails here instead of hanging the write later)."""
    try:
        fd = os.open(target, os.O_WRONLY | os.O_APPEND | os.O_NONBLOCK | os.O_NOCTTY)
    except OSError as error:
        raise InputError(f"{option} {target}: cannot write ({error.strerror})") from None
    os.close(fd)


#: How the probe file is created: as ``tempfile.mkstemp`` creates one (a new name only,
#: never a link followed), without importing tempfile and random into every start-up.
_PROBE_FLAGS = os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC


def _probe(directory: Path, target: Path, option: str) -> None:
    """Create and remove a file in ``directory``: the only check root cannot pass wrongly."""
    for _ in range(100):
        name = os.path.join(directory, f".ads_rca_probe_{os.urandom(6).hex()}")
        try:
            fd = os.open(name, _PROBE_FLAGS, 0o600)
        except FileExistsError:
            continue
        except OSError as error:
            raise InputError(
                f"{option} {target}: cannot write in {directory} ({error.strerror})"
            ) from None
        os.close(fd)
        os.unlink(name)
        return
    raise InputError(f"{option} {target}: cannot write in {directory} (no free file name)")
