"""The runs of a batch: ``INPUTS`` (log folders, bags, globs, text files of paths) expanded.

Every input is checked before any work starts, and refused in one line: a path that does not
exist, a glob that matches nothing, a paths file with a line that is no usable path (control
characters, a missing path). A paths file lists one run per line; blank lines and lines
starting with ``#`` are skipped, relative paths are relative to the file's folder.

Each run gets a **run id**: the first 16 hex digits of the SHA-256 of its resolved absolute
path (``os.path.realpath``). The same run reached by two inputs is diagnosed once, and the
id is stable across batches on the same machine (``--resume`` matches on it); on a cluster
the same shared path gives the same id on every node.
"""

from __future__ import annotations

import glob
import hashlib
import os
from dataclasses import dataclass
from pathlib import Path

from ads_rca.errors import InputError
from ads_rca.foundation.text import printable

#: Suffixes of single-file bags (a run by themselves, never a paths file).
BAG_SUFFIXES = (".mcap", ".db3")
#: A paths file larger than this is refused (a list of a million runs is ~100 MB).
MAX_PATHS_FILE_BYTES = 256 * 1024 * 1024
_GLOB_CHARS = frozenset("*?[")


@dataclass(frozen=True)
class Run:
    """One run to diagnose: its resolved path and id."""

    run_id: str
    path: str


def run_id(path: str | os.PathLike[str]) -> str:
    """The stable id of a run: a hash of its resolved absolute path (see the module doc)."""
    resolved = os.path.realpath(os.fspath(path))
    return hashlib.sha256(resolved.encode("utf-8", "surrogateescape")).hexdigest()[:16]


def expand_inputs(inputs: list[str]) -> list[Run]:
    """The runs ``inputs`` name, in order, each once; :class:`InputError` for a bad input."""
    if not inputs:
        raise InputError("no input: give log folders, bags, globs or a text file of paths")
    runs: dict[str, Run] = {}
    for item in inputs:
        for path in _expand(item):
            run = Run(run_id(path), os.path.realpath(path))
            runs.setdefault(run.run_id, run)
    if not runs:
        raise InputError("the inputs name no run")
    return list(runs.values())


def _expand(item: str) -> list[str]:
    _check_text(item, "input")
    if os.path.lexists(item):
        if os.path.isdir(item) or item.endswith(BAG_SUFFIXES):
            return [item]
        if os.path.isfile(item):
            return read_paths_file(item)
        raise InputError(f"{printable(item)}: not a log folder, a bag or a text file of paths")
    if _GLOB_CHARS & set(item):
        matches = sorted(glob.glob(item, recursive=True))
        if not matches:
            raise InputError(f"{printable(item)}: the glob matches nothing")
        runs = [m for m in matches if os.path.isdir(m) or m.endswith(BAG_SUFFIXES)]
        if not runs:
            raise InputError(
                f"{printable(item)}: the glob matches {len(matches)} path(s), "
                "none a log folder or a bag"
            )
        return runs
    raise InputError(f"{printable(item)}: no such log folder, bag or paths file")


def read_paths_file(name: str) -> list[str]:
    """The runs a text file lists (see the module docstring); each must exist."""
    try:
        size = os.path.getsize(name)
        if size > MAX_PATHS_FILE_BYTES:
            raise InputError(f"{printable(name)}: a paths file of {size} bytes is too large")
        with open(name, "rb") as handle:
            data = handle.read()
    except OSError as error:
        raise InputError(f"{printable(name)}: cannot read ({error.strerror})") from None
    if b"\0" in data:
        raise InputError(f"{printable(name)}: binary data, not a text file of paths")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise InputError(
            f"{printable(name)}: not UTF-8 text (byte {error.start}); expected one path a line"
        ) from None
    base = Path(name).parent
    paths: list[str] = []
    for number, raw in enumerate(text.splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        where = f"{name}:{number}"
        _check_text(line, where)
        path = line if os.path.isabs(line) else os.fspath(base / line)
        if not os.path.lexists(path):
            raise InputError(f"{printable(where)}: {printable(line)}: no such log folder or bag")
        if not (os.path.isdir(path) or path.endswith(BAG_SUFFIXES)):
            raise InputError(f"{printable(where)}: {printable(line)}: not a log folder or a bag")
        paths.append(path)
    if not paths:
        raise InputError(f"{printable(name)}: lists no path")
    return paths


def _check_text(text: str, where: str) -> None:
    if any(ord(c) < 32 or ord(c) == 127 for c in text):
        raise InputError(f"{printable(where)}: {printable(text)}: control characters in a path")
