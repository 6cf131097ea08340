"""Reads rosbag2 bags (MCAP or sqlite3) whose topics follow our contract back into a RunLog.

A bag recorded from the player (``recorder`` node), written by ``ads-rca convert``, or made
by a stack whose topics carry the contract's types under other names (mapped by a remapping
YAML, see docs/topics.md) is replayed into the same :class:`RunLogAssembler` the live
subscribers use, so a bag and a DDS stream rebuild the same log. Pure:
:mod:`ads_rca.sources.bag.storage` reads the storage files, :mod:`ads_rca.contract.rosmsg` turns CDR
into message objects; no rclpy.

Accepted paths: a bag directory with ``metadata.yaml``; a directory holding one ``.mcap`` /
``.db3`` file (a recording whose writer was killed before writing ``metadata.yaml``); a bare
``.mcap`` or ``.db3`` file. A bag nobody checked is read as far as it can be: a cut or
damaged storage file gives what it holds (a killed recorder's MCAP up to its last complete
chunk), a message that cannot be decoded is skipped, and the storage's own topics and types
are trusted over ``metadata.yaml``; each of these is a Problem in the log, so ``inspect``,
``diagnose`` and the JSON list it.

:func:`load_bag` also keeps the type definitions the storage carries;
:meth:`BagContents.types` makes them a type store of the bag's own
(:mod:`ads_rca.sources.bag.message_types`), for a stack's messages read without their packages. The
contract's topics are decoded as always, through :mod:`ads_rca.contract.rosmsg`.

Only regular files are read (:mod:`ads_rca.foundation.files`): a FIFO or a device named like a
storage file or ``metadata.yaml`` is found (by name and ``stat``, which never blocks) and
reported, never opened: a Problem when other storage files can be read, else InputError.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import yaml

from ads_rca.contract import rosmsg, topics
from ads_rca.contract.assembler import RunLogAssembler
from ads_rca.contract.errors import MalformedMessage
from ads_rca.errors import InputError
from ads_rca.foundation.files import Unreadable, read_regular
from ads_rca.foundation.progress import Progress, tracked
from ads_rca.foundation.text import short_repr
from ads_rca.foundation.yaml_files import load_yaml
from ads_rca.model import RunLog
from ads_rca.problems import IGNORED, SKIPPED_FILE, USED_DEFAULT, Problem
from ads_rca.sources.bag.message_types import DECODE_ERRORS
from ads_rca.sources.bag.paths import BAG_SUFFIXES, METADATA_YAML, is_bag, present, storage_files
from ads_rca.sources.bag.storage import (
    KEPT_BEFORE_CUT,
    BagMessage,
    StorageRead,
    TopicCount,
    counts_of,
    read_mcap,
    read_storage,
)

if TYPE_CHECKING:
    from ads_rca.sources.bag.message_types import BagTypes

#: A rosbag2 metadata.yaml is a few KiB per topic; anything this large is not one.
MAX_METADATA_YAML_BYTES = 64 << 20
_IGNORED_YAML = "metadata.yaml ignored; the storage files are read"
_TRUSTED_STORAGE = "the storage's own channels and types are used"

__all__ = ["BagMessage", "is_bag", "iter_bag", "iter_mcap_stream", "load_bag", "read_bag"]


@dataclass(frozen=True)
class Remap:
    """Their topic name → our topic key; optional metadata.json document for bags without
    ``run/metadata``."""

    topics: dict[str, str] = field(default_factory=dict)
    metadata: dict[str, Any] | None = None


def load_remap(path: str | os.PathLike[str]) -> Remap:
    """A remapping YAML: ``{their_topic: our_topic_key, ..., metadata: {...}}``."""
    document = load_yaml(path, "remapping") or {}
    if not isinstance(document, dict):
        raise InputError(f"{path}: a remapping file is a mapping of topic → topic key")
    metadata = document.pop("metadata", None)
    mapping: dict[str, str] = {}
    for theirs, ours in document.items():
        # Names are strings: str() of anything else could be a billion-laughs expansion.
        if not isinstance(theirs, str) or ours not in topics.ALL_TOPICS:
            shown = short_repr(ours if isinstance(theirs, str) else theirs)
            raise InputError(f"{path}: {shown} is not a contract topic key {topics.ALL_TOPICS}")
        mapping[theirs] = ours
    if metadata is not None and not isinstance(metadata, dict):
        raise InputError(f"{path}: 'metadata' must be a mapping (a metadata.json document)")
    return Remap(mapping, metadata)


# --- locating and reading -----------------------------------------------------------------


@dataclass
class BagContents:
    """Every message of a bag (log-time order), the storage's own topics and type
    definitions, and the defects found in its files and in ``metadata.yaml``."""

    messages: list[BagMessage]
    topics: dict[str, str]
    problems: list[Problem]
    #: type → (encoding, text) the storage files carry (see :class:`StorageRead`).
    definitions: dict[str, tuple[str, str]] = field(default_factory=dict)
    #: the bag as given (names it in errors)
    path: str = ""

    def types(
        self,
        msg_path: str | os.PathLike[str] | Sequence[str | os.PathLike[str]] | None = None,
    ) -> BagTypes:
        """The bag's message types: its own definitions, Kilted's standard types and the
        ``.msg`` files under ``msg_path`` (see :mod:`ads_rca.sources.bag.message_types`)."""
        from ads_rca.sources.bag.message_types import BagTypes

        return BagTypes(self.path, self.definitions, msg_path)


def load_bag(path: str | os.PathLike[str]) -> BagContents:
    """Read a bag's storage files (see the module docstring), checking metadata.yaml against
    them. Raises InputError only when no storage file can be read at all."""
    info, problems, files = locate_bag(path)
    reads = read_files(files, info, problems, read_storage)
    messages = sorted(
        (m for read in reads for m in read.messages), key=lambda m: m.log_time_ns
    )  # stable: file order within a log time
    storage_topics: dict[str, str] = {}
    definitions: dict[str, tuple[str, str]] = {}
    for read in reads:
        problems.extend(read.problems)
        for name, msg_type in read.topics.items():
            storage_topics.setdefault(name, msg_type)
        for msg_type, definition in read.definitions.items():
            if definitions.setdefault(msg_type, definition) != definition:
                issue = f"a definition of {msg_type} other than the first file's"
                problems.append(Problem(read.file.name, msg_type, issue, "the first one is used"))
    if info is not None and not any(read.truncated for read in reads):
        problems.extend(disagreements(info, storage_topics, counts_of(messages)))
    elif info is not None:  # a cut file already says what it lost: no count compared
        problems.extend(disagreements(info, storage_topics, None))
    return BagContents(messages, storage_topics, problems, definitions, os.fspath(path))


def locate_bag(
    path: str | os.PathLike[str],
) -> tuple[dict[str, Any] | None, list[Problem], list[Path]]:
    """A bag's ``metadata.yaml`` document (None when absent or unusable), the problems
    found in it, and its storage files (InputError when ``path`` is no bag)."""
    p = Path(path)
    if p.is_dir():
        info, problems = _metadata_yaml(p)
        return info, problems, _bag_files(p, info, problems)
    if p.suffix in BAG_SUFFIXES and present(p):
        return None, [], [p]
    if p.is_file():
        raise InputError(f"{p}: not a bag file (.mcap or .db3)")
    raise InputError(f"{p}: no such bag")


Read = TypeVar("Read", bound=StorageRead)


def read_files(
    files: list[Path],
    info: dict[str, Any] | None,
    problems: list[Problem],
    read: Callable[[Path, int | None], Read],
) -> list[Read]:
    """Each storage file read by ``read`` (given what metadata.yaml announces it holds);
    one that cannot be read at all is a Problem when another one can (InputError, the
    first file's reason, when none can)."""
    reads: list[Read] = []
    failed: list[tuple[Path, InputError]] = []
    for file in files:
        try:
            reads.append(read(file, _announced_messages(info, file)))
        except InputError as error:
            failed.append((file, error))
    if not reads:
        raise failed[0][1]
    for file, refused in failed:
        issue = str(refused).removeprefix(f"{file}: ")
        problems.append(Problem(file.name, "", issue, SKIPPED_FILE))
    return reads


def _metadata_yaml(directory: Path) -> tuple[dict[str, Any] | None, list[Problem]]:
    """The ``rosbag2_bagfile_information`` document (None when absent or unusable)."""
    path = directory / METADATA_YAML
    if not present(path):
        return None, []
    try:
        # libyaml's safe loader when present: the pure-Python one takes ~80 ms per bag.
        loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
        data = read_regular(path, MAX_METADATA_YAML_BYTES)
        if isinstance(data, Unreadable):
            raise OSError(data.issue.replace("(max_file_mb)", "").strip())
        document = yaml.load(data.decode("utf-8"), Loader=loader)
    except (OSError, UnicodeDecodeError, yaml.YAMLError, RecursionError) as error:
        detail = str(error).splitlines()[0] if str(error) else type(error).__name__
        return None, [Problem(METADATA_YAML, "", f"unreadable: {detail}", _IGNORED_YAML)]
    info = document.get("rosbag2_bagfile_information") if isinstance(document, dict) else None
    if not isinstance(info, dict):
        issue = "no rosbag2_bagfile_information mapping"
        return None, [Problem(METADATA_YAML, "", issue, _IGNORED_YAML)]
    return info, []


def _bag_files(directory: Path, info: dict[str, Any] | None, problems: list[Problem]) -> list[Path]:
    """The storage files of a bag directory: metadata.yaml's list when it names files that
    exist, else the one .mcap/.db3 the directory holds."""
    listed = info.get("relative_file_paths") if info is not None else None
    files: list[Path] = []
    if isinstance(listed, list):
        for name in listed:
            candidate = directory / str(name)
            inside = Path(str(name)).name == str(name)  # no path into other directories
            if inside and present(candidate) and candidate.suffix in BAG_SUFFIXES:
                files.append(candidate)
            else:
                problems.append(
                    Problem(
                        METADATA_YAML,
                        "relative_file_paths",
                        f"lists {str(name)!r}, which is not a storage file of the bag",
                        IGNORED,
                    )
                )
    if files:
        return files
    found = split_order(storage_files(directory))
    if not found:
        raise InputError(f"{directory}: not a bag (no usable metadata.yaml and no .mcap/.db3)")
    if info is not None:
        names = ", ".join(f.name for f in found)
        problems.append(
            Problem(
                METADATA_YAML,
                "relative_file_paths",
                f"names no storage file of the bag; {names} read instead",
                USED_DEFAULT,
            )
        )
    return found


def split_order(files: list[Path]) -> list[Path]:
    """Storage files in the order rosbag2 splits a recording (``x_0``, ``x_1``, ...,
    ``x_10``: by the number after the last ``_``, then by name)."""

    def key(file: Path) -> tuple[str, int, str]:
        stem, _, number = file.stem.rpartition("_")
        return (stem, int(number), file.name) if number.isdigit() else (file.stem, -1, file.name)

    return sorted(files, key=key)


def _announced_messages(info: dict[str, Any] | None, file: Path) -> int | None:
    """How many messages metadata.yaml says ``file`` holds (None when it does not say)."""
    entries = info.get("files") if info is not None else None
    for entry in entries if isinstance(entries, list) else []:
        if isinstance(entry, dict) and entry.get("path") == file.name:
            count = entry.get("message_count")
            return count if isinstance(count, int) and not isinstance(count, bool) else None
    return None


def _yaml_topics(info: dict[str, Any]) -> dict[str, tuple[str, int | None]]:
    """metadata.yaml's topic name → (type, message count)."""
    out: dict[str, tuple[str, int | None]] = {}
    entries = info.get("topics_with_message_count")
    for entry in entries if isinstance(entries, list) else []:
        meta = entry.get("topic_metadata") if isinstance(entry, dict) else None
        if isinstance(meta, dict) and isinstance(meta.get("name"), str):
            count = entry.get("message_count")
            out[meta["name"]] = (
                str(meta.get("type", "")),
                count if isinstance(count, int) and not isinstance(count, bool) else None,
            )
    return out


def disagreements(
    info: dict[str, Any],
    storage: dict[str, str],
    counts: Mapping[str, TopicCount] | None,
) -> list[Problem]:
    """Every way metadata.yaml differs from the storage files, which are trusted and used
    (``counts``: the storage's messages per topic; None when a file was cut, which says
    itself what it lost)."""
    declared = _yaml_topics(info)
    out: list[Problem] = []
    for name, msg_type in sorted(storage.items()):
        if name not in declared:
            out.append(
                Problem(
                    METADATA_YAML,
                    name,
                    f"topic missing (the storage holds it, type {msg_type})",
                    _TRUSTED_STORAGE,
                )
            )
        elif rosmsg.normalise_type(declared[name][0]) != rosmsg.normalise_type(msg_type):
            out.append(
                Problem(
                    METADATA_YAML,
                    name,
                    f"type {declared[name][0]}, the storage's is {msg_type}",
                    _TRUSTED_STORAGE,
                )
            )
    out.extend(
        Problem(METADATA_YAML, name, "topic not in the storage files", IGNORED, "warning")
        for name in sorted(set(declared) - set(storage))
    )
    if counts is not None:
        for name, (_type, count) in sorted(declared.items()):
            held = counts.get(name, TopicCount()).count
            if name in storage and count is not None and count != held:
                out.append(
                    Problem(
                        METADATA_YAML,
                        name,
                        f"message_count {count}, the storage holds {held}",
                        _TRUSTED_STORAGE,
                        severity="warning",
                    )
                )
    return out


def iter_bag(path: str | os.PathLike[str]) -> Iterator[BagMessage]:
    """Every message of a bag in log-time order (what a damaged file still holds)."""
    yield from load_bag(path).messages


def iter_mcap_stream(path: str | os.PathLike[str]) -> Iterator[BagMessage]:
    """Every message an MCAP file holds, in file order, up to where it is cut."""
    yield from read_mcap(Path(path)).messages


# --- rebuilding the log -------------------------------------------------------------------


def detect_namespace(names: list[str]) -> str:
    """The contract namespace a bag's topic names use (default when none matches)."""
    anchors = (topics.METADATA, topics.FRAME, topics.STATUS, *topics.DATA_TOPICS)
    votes: dict[str, int] = {}
    for name in names:
        for key in anchors:
            if name.endswith("/" + key):
                namespace = topics.normalise_namespace(name[: -len(key) - 1])
                votes[namespace] = votes.get(namespace, 0) + 1
    if not votes:
        return topics.DEFAULT_NAMESPACE
    return max(votes, key=lambda ns: votes[ns])


def topic_keys(
    names: list[str], remap: Remap | None = None, namespace: str | None = None
) -> dict[str, str]:
    """Bag topic name → contract key, by remapping or by the contract's names."""
    if remap is not None and remap.topics:
        return {name: key for name, key in remap.topics.items() if name in names}
    ns = detect_namespace(names) if namespace is None else namespace
    full = topics.topic_names(ns)
    return {full[key]: key for key in topics.ALL_TOPICS if full[key] in names}


class NoRunMetadata(InputError):
    """A bag read with this project's contract has no run/metadata: often a real stack's
    recording read without its profile (the message then says which)."""


def _profile_hint(contents: BagContents) -> str:
    """The error's ending "…: add --profile NAME" when the bag holds messages of a built-in
    stack profile's types on its topics (the rule ``inspect`` recommends by, never topic
    names alone: a declared topic without messages gives nothing); else nothing."""
    from ads_rca.sources.bag.survey import (  # the survey reads bags: no cycle
        builtin_profiles,
        survey_contents,
    )

    stacks = [profile for profile in builtin_profiles() if not profile.contract]
    recommendation = survey_contents(contents, profiles=stacks, look_up=False).recommendation
    name = recommendation.profile if recommendation is not None else None
    return f"; its topics are the {name} profile's: add --profile {name}" if name else ""


def read_bag(
    path: str | os.PathLike[str],
    remap: Remap | str | os.PathLike[str] | None = None,
    namespace: str | None = None,
    progress: Progress | None = None,
    contents: BagContents | None = None,
) -> RunLog:
    """Rebuild the RunLog a bag carries (see the module docstring for accepted paths);
    ``progress`` sees each message as it is decoded; ``contents``: the bag already read by
    :func:`load_bag` (``inspect`` lists its topics too).

    Every defect of the bag (a cut file, an undecodable message, a metadata.yaml that
    disagrees with the storage) is a Problem in the log; InputError only when nothing
    usable is left (no storage file readable, or no run/metadata)."""
    if remap is not None and not isinstance(remap, Remap):
        remap = load_remap(remap)
    contents = contents if contents is not None else load_bag(path)
    problems = list(contents.problems)
    keys = topic_keys(sorted(contents.topics), remap, namespace)
    usable = _usable_topics(keys, contents.topics, problems)
    assembler = RunLogAssembler()
    for message in tracked(contents.messages, progress):
        key = usable.get(message.topic)
        if key is not None:
            _add_message(assembler, key, message, problems)
    if assembler.metadata_document is None and remap is not None and remap.metadata:
        assembler.metadata_document = dict(remap.metadata)
    if assembler.metadata_document is None:
        metadata_topics = {name for name, key in keys.items() if key == topics.METADATA}
        why = [p for p in problems if p.field in metadata_topics and p.severity == "error"]
        why += [p for p in problems if p.action == KEPT_BEFORE_CUT]
        why += [p for p in problems if p.file.endswith(BAG_SUFFIXES) and p.severity == "error"]
        cut = [f"{p.file}: {p.field}: {p.issue}" for p in why]
        raise NoRunMetadata(
            f"{path}: the bag has no run/metadata message (map one, or give 'metadata' in "
            "the remapping file)" + (f"; {cut[0]}" if cut else "") + _profile_hint(contents)
        )
    try:
        log = assembler.build()
    except MalformedMessage as error:
        reason = error.__cause__ or error  # the reader's own error, as always said
        raise InputError(f"{path}: cannot rebuild the log (run/metadata): {reason!r}") from error
    if not assembler.markers:  # no frame markers (a stack's bag): actors stamps are frames
        log = replace(log, frames=tuple(sorted(log.actors)))
    log.problems.extend(problems)
    return replace(log, source=str(path))


def _usable_topics(
    keys: dict[str, str], types: dict[str, str], problems: list[Problem]
) -> dict[str, str]:
    """Bag topic → contract key, for topics whose stored type is the contract's."""
    usable: dict[str, str] = {}
    for name, key in keys.items():
        expected = rosmsg.type_name(topics.message_types()[key])
        if rosmsg.normalise_type(types[name]) == expected:
            usable[name] = key
        else:
            problems.append(
                Problem(
                    name,
                    "type",
                    f"stored type {types[name]}, the contract's {key} is {expected}",
                    "topic skipped",
                )
            )
    return usable


def _add_message(
    assembler: RunLogAssembler, key: str, message: BagMessage, problems: list[Problem]
) -> None:
    """Decode one message into the assembler; a damaged one is skipped and reported.

    Data messages are converted to model records here too, so a message that decodes into
    something no record can be made of is refused before the assembler keeps it."""
    expected = rosmsg.type_name(topics.message_types()[key])
    try:
        msg = rosmsg.deserialize(message.data, expected)
        if key in topics.DATA_TOPICS:
            topics.message_to_record(key, msg, 1)
        assembler.add(key, msg)
    except DECODE_ERRORS as error:
        detail = str(error).splitlines()[0] if str(error) else type(error).__name__
        problems.append(
            Problem(
                message.source or message.topic,
                message.topic,
                f"message at log time {message.log_time_ns} ns: cannot decode this {expected}: "
                f"{detail}",
                "message skipped",
            )
        )
