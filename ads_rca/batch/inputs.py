"""The runs of a batch: ``INPUTS`` (log folders, bags, globs, text files of paths) expanded.

Every input is checked before any work starts, and refused in one line: a path that does not
exist, a glob that matches nothing, a paths file with a line that is no usable path (control
characters, a missing path). A paths file lists one run per line; blank lines and lines
starting with ``#`` are skipped, relative paths are relative to the file's folder; a leading
UTF-8 byte order mark is dropped.

A glob is expanded as ``glob.glob(pattern, recursive=True)`` would (``**`` any number of
folders, names starting with ``.`` only matched by a part starting with ``.``, symlinks to
folders followed), by a walk of our own with bounds: ``glob`` follows a symlink loop
(``a/b -> ..``) until the path is too long, so a tree with two loops is 2**40 paths
(still expanding at 30 s, 330 MB). Here each ``**`` walk descends into a folder once, by
its ``(st_dev, st_ino)``: a folder inside itself (a loop) or reached again by another path
(two symlinks to it) is matched but not walked again, and at most :data:`MAX_GLOB_DEPTH`
folders deep; what was skipped is said, one line per kind with its count (the ``note``
callback). A glob whose walk lists more than :data:`MAX_GLOB_ENTRIES` entries is refused
(narrow it, or list the runs in a paths file). Measured in ``bench/bench_batch_glob.py``.

Each run gets a **run id**: the first 16 hex digits of the SHA-256 of its resolved absolute
path (``os.path.realpath``), where it is read too, unless only the name it was given says
its format (:func:`read_path`). The same run reached by two inputs is diagnosed once, and the
id is stable across batches on the same machine (``--resume`` matches on it); on a cluster
the same shared path gives the same id on every node.
"""

from __future__ import annotations

import fnmatch
import hashlib
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

from ads_rca.errors import InputError
from ads_rca.foundation.text import printable

#: Suffixes of single-file bags (a run by themselves, never a paths file).
BAG_SUFFIXES = (".mcap", ".db3")
#: A paths file larger than this is refused (a list of a million runs is ~100 MB).
MAX_PATHS_FILE_BYTES = 256 * 1024 * 1024
_GLOB_CHARS = frozenset("*?[")
#: Directory entries a glob's walk may list, all its levels together: a tree past this is
#: refused (2 million is a thousand runs of 2,000 files each under ``**``, a few seconds).
MAX_GLOB_ENTRIES = 2_000_000
#: Folders a ``**`` descends below where it starts; deeper ones are matched, not walked.
MAX_GLOB_DEPTH = 64


@dataclass(frozen=True)
class Run:
    """One run to diagnose: the path it is read at (:func:`read_path`) and its id."""

    run_id: str
    path: str


def run_id(path: str | os.PathLike[str]) -> str:
    """The stable id of a run: a hash of its resolved absolute path (see the module doc)."""
    resolved = os.path.realpath(os.fspath(path))
    return hashlib.sha256(resolved.encode("utf-8", "surrogateescape")).hexdigest()[:16]


def read_path(path: str) -> str:
    """Where a run is read: its resolved path, unless only the name it was given says its
    format (a bag linked from a content-addressed store, DVC-style: ``crash.mcap -> store/
    3f9a...``, issue 43), when the link itself is read."""
    resolved, given = os.path.realpath(path), os.path.abspath(path)
    if given.endswith(BAG_SUFFIXES) and not resolved.endswith(BAG_SUFFIXES):
        return given
    return resolved


def expand_inputs(inputs: list[str], note: Callable[[str], None] = lambda line: None) -> list[Run]:
    """The runs ``inputs`` name, in order, each once; :class:`InputError` for a bad input.
    ``note`` is given one line per kind of thing a glob's walk skipped."""
    if not inputs:
        raise InputError("no input: give log folders, bags, globs or a text file of paths")
    runs: dict[str, Run] = {}
    for item in inputs:
        for path in _expand(item, note):
            run = Run(run_id(path), read_path(path))
            runs.setdefault(run.run_id, run)
    if not runs:
        raise InputError("the inputs name no run")
    return list(runs.values())


def _expand(item: str, note: Callable[[str], None]) -> list[str]:
    _check_text(item, "input")
    if os.path.lexists(item):
        if os.path.isdir(item) or item.endswith(BAG_SUFFIXES):
            return [item]
        if os.path.isfile(item):
            return read_paths_file(item)
        raise InputError(f"{printable(item)}: not a log folder, a bag or a text file of paths")
    if _GLOB_CHARS & set(item):
        walk = _Walk(item)
        matches = 0
        runs: list[str] = []
        for path, is_dir in walk.matches():
            matches += 1
            if is_dir or path.endswith(BAG_SUFFIXES):
                runs.append(path)
        for line in walk.skipped():
            note(f"{printable(item)}: {line}")
        if not matches:
            raise InputError(f"{printable(item)}: the glob matches nothing")
        if not runs:
            raise InputError(
                f"{printable(item)}: the glob matches {matches} path(s), none a log folder or a bag"
            )
        return sorted(runs)
    raise InputError(f"{printable(item)}: no such log folder, bag or paths file")


class _Walk:
    """The paths a glob ``pattern`` matches, found by a bounded walk (module docstring)."""

    def __init__(self, pattern: str) -> None:
        self.pattern = pattern
        self.entries = 0
        self.loops = 0
        self.again = 0
        self.too_deep = 0
        self.unlisted = 0
        self.unlisted_why = ""

    def matches(self) -> Iterator[tuple[str, bool]]:
        """Each matching path and whether it is a folder (symlinks followed)."""
        parts = self.pattern.split(os.sep)
        base = os.sep if parts[0] == "" else ""
        last_dir_only = parts[-1] == ""  # "runs/*/": folders only
        parts = [part for part in parts if part]
        while parts and not _GLOB_CHARS & set(parts[0]):
            base = os.path.join(base, parts.pop(0))
        if parts:
            yield from self._match(base, parts, last_dir_only)

    def skipped(self) -> list[str]:
        """One line per kind of folder not walked, with its count."""
        lines = []
        if self.loops:
            lines.append(f"{self.loops} symlink loop(s) not followed (a folder inside itself)")
        if self.again:
            lines.append(f"{self.again} folder(s) reached again by another path, searched once")
        if self.too_deep:
            lines.append(
                f"{self.too_deep} folder(s) more than {MAX_GLOB_DEPTH} levels below '**' "
                "not searched"
            )
        if self.unlisted:
            lines.append(f"{self.unlisted} folder(s) could not be listed ({self.unlisted_why})")
        return lines

    def _match(
        self, folder: str, parts: list[str], last_dir_only: bool
    ) -> Iterator[tuple[str, bool]]:
        """The paths under ``folder`` that ``parts`` (the pattern's rest) match."""
        part, rest = parts[0], parts[1:]
        dir_only = bool(rest) or last_dir_only
        found: Iterator[tuple[str, bool]] | list[tuple[str, bool]]
        if part == "**":
            found = self._descend(folder, dir_only)
        elif _GLOB_CHARS & set(part):
            found = self._level(folder, part, dir_only)
        else:
            path = os.path.join(folder, part)
            is_dir = os.path.isdir(path)
            found = [(part, is_dir)] if is_dir or (not dir_only and os.path.lexists(path)) else []
        for name, is_dir in found:
            path = os.path.join(folder, name)
            if not path:  # "**" at the start: its empty match is the current folder (as glob)
                continue
            if not rest:
                yield (path + os.sep if last_dir_only and name else path), is_dir
            elif is_dir:
                yield from self._match(path, rest, last_dir_only)

    def _level(self, folder: str, part: str, dir_only: bool) -> Iterator[tuple[str, bool]]:
        """Names in ``folder`` matching the wildcard ``part``."""
        hidden = part.startswith(".")
        for entry in self._list(folder):
            if (hidden or not entry.name.startswith(".")) and fnmatch.fnmatchcase(entry.name, part):
                is_dir = _is_dir(entry)
                if is_dir or not dir_only:
                    yield entry.name, is_dir

    def _descend(self, top: str, dir_only: bool) -> Iterator[tuple[str, bool]]:
        """``**``: "" (``top`` itself), then every path below it, each folder walked once."""
        yield "", True
        try:
            info = os.stat(top or ".")
        except OSError:
            return
        root = (info.st_dev, info.st_ino)
        parent: dict[tuple[int, int], tuple[int, int] | None] = {root: None}
        stack = [("", 0, root)]
        while stack:
            relative, depth, key = stack.pop()
            for entry in self._list(os.path.join(top, relative)):
                if entry.name.startswith("."):
                    continue
                is_dir = _is_dir(entry)
                if dir_only and not is_dir:
                    continue
                path = os.path.join(relative, entry.name)
                yield path, is_dir
                if not is_dir:
                    continue
                try:
                    info = entry.stat()
                except OSError:
                    continue
                child = (info.st_dev, info.st_ino)
                if child in parent:
                    if _is_ancestor(child, key, parent):
                        self.loops += 1
                    else:
                        self.again += 1
                elif depth >= MAX_GLOB_DEPTH:
                    self.too_deep += 1
                else:
                    parent[child] = key
                    stack.append((path, depth + 1, child))

    def _list(self, folder: str) -> list[os.DirEntry[str]]:
        """The entries of ``folder`` (none if it is no folder), counted against the bound."""
        entries: list[os.DirEntry[str]] = []
        try:
            with os.scandir(folder or ".") as listing:
                for entry in listing:
                    self.entries += 1
                    if self.entries > MAX_GLOB_ENTRIES:
                        raise InputError(
                            f"{printable(self.pattern)}: the glob's walk passed "
                            f"{MAX_GLOB_ENTRIES:,} entries: narrow it (e.g. 'campaign/*/run_*') "
                            "or list the runs in a text file of paths"
                        )
                    entries.append(entry)
        except (FileNotFoundError, NotADirectoryError):
            pass
        except OSError as error:
            self.unlisted += 1
            self.unlisted_why = self.unlisted_why or (error.strerror or str(error))
        return entries


def _is_dir(entry: os.DirEntry[str]) -> bool:
    try:
        return entry.is_dir()
    except OSError:
        return False


def _is_ancestor(
    key: tuple[int, int], of: tuple[int, int], parent: dict[tuple[int, int], tuple[int, int] | None]
) -> bool:
    """Whether folder ``key`` is ``of`` or one of the folders above it in the walk."""
    current: tuple[int, int] | None = of
    while current is not None:
        if current == key:
            return True
        current = parent[current]
    return False


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
    # An editor's UTF-8 byte order mark (Notepad's) is no part of the first path.
    text = text.removeprefix("\ufeff")
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
