"""Reads the messages of one rosbag2 storage file (MCAP or sqlite3), salvaging damaged files.

Why not a library reader: a bag from a killed recorder, a copy cut short or a damaged disk
must still give what it holds, and say what it lost. rosbags' readers refuse an MCAP without
its summary and trust ``metadata.yaml``; mcap's stream reader stops silently at a cut and
allocates whatever length a damaged record header claims. So this module walks the file
itself:

- MCAP: record by record from the start magic, every length checked against the bytes
  that remain before anything is read or decompressed. Complete chunks are decoded one by
  one (a chunk that cannot be decompressed is reported and skipped); in an uncompressed chunk
  cut by the end of the file, the complete message records before the cut are kept (each
  has its own length, so nothing past the cut is guessed). A file without footer and end
  magic is reported as truncated, with how many messages were recovered.
- sqlite3: rows are read one by one from a read-only (immutable) connection until the
  database reports damage; the header's page count against the file size tells a truncated
  file that sqlite would read quietly.

A storage file is opened only if it is a regular file, checked on the opened descriptor
(:func:`ads_rca.foundation.files.open_regular`): a FIFO named ``x_0.mcap`` would block forever, a
symlink to ``/dev/zero`` would be read until memory runs out. sqlite opens the database by
name, so it is given ``/proc/self/fd/N`` of the checked descriptor: a name swapped for a
FIFO after the check is never opened.

Topics and types come from the storage itself (MCAP channels and schemas, the sqlite3
``topics`` table), never from ``metadata.yaml``. So do the types' definitions (MCAP schema
data, the sqlite3 ``message_definitions`` table of rosbag2 >= Iron), kept as text for
:mod:`ads_rca.sources.bag.message_types`: a recording carries the layouts of its own messages. A
definition
over :data:`MAX_DEFINITION_BYTES` is reported and ignored. Pure Python, no rclpy. Nothing
raises but :class:`~ads_rca.errors.InputError`, when the file holds nothing readable at all.

:func:`list_storage` lists a file instead of reading it (``inspect`` of a bag of any size
and any types): each topic's count and first and last log time, never a message kept. A
sqlite3 file is counted by sqlite itself (``GROUP BY topic_id``: no blob fetched); an MCAP
file from its summary, the statistics for the counts and each chunk's message index records
(16 bytes a message) for the times, no chunk decompressed; an MCAP without a summary that
adds up, and a damaged sqlite3 file, from the same salvaging walk as reading, counting.
"""

from __future__ import annotations

import os
import shutil
import sqlite3
import struct
import tempfile
import zlib
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO, Protocol

import numpy as np
import numpy.typing as npt

from ads_rca.errors import InputError
from ads_rca.foundation.files import Unreadable, open_regular
from ads_rca.foundation.text import short_repr
from ads_rca.problems import IGNORED, Problem, Severity
from ads_rca.sources.errors import CorruptRecord

MCAP_MAGIC = b"\x89MCAP0\r\n"
#: Largest uncompressed chunk accepted (rosbag2 writes 768 KiB, our recorder 1 MiB): a
#: damaged size field must not make the reader allocate gigabytes.
MAX_CHUNK_BYTES = 1 << 30
#: Largest message definition kept (Autoware's PredictedObjects with every dependency is a
#: few KiB): parsing text costs time, and a definition this large is not a real one.
MAX_DEFINITION_BYTES = 1 << 20

# MCAP opcodes (https://mcap.dev/spec).
_HEADER, _FOOTER, _SCHEMA, _CHANNEL, _MESSAGE, _CHUNK, _DATA_END = 1, 2, 3, 4, 5, 6, 15
_RECORD_HEAD = 9  # opcode (u8) + length (u64)
_CHUNK_HEAD = 8 + 8 + 8 + 4 + 4  # start, end, uncompressed size, crc, compression length
_MESSAGE_HEAD = 2 + 4 + 8 + 8  # channel, sequence, log time, publish time

KEPT_BEFORE_CUT = "the messages before the cut are used; the rest of the recording is lost"
SKIPPED_MESSAGES = "its messages skipped"
IGNORED_DEFINITION = "definition ignored"


@dataclass(frozen=True)
class BagMessage:
    topic: str
    msg_type: str
    log_time_ns: int
    data: bytes
    #: name of the storage file it was read from (for problems)
    source: str = ""


@dataclass
class StorageRead:
    """What one storage file holds: its messages (file order), its own topics, its defects."""

    file: Path
    messages: list[BagMessage] = field(default_factory=list)
    #: topic name → type, from the storage's channels/schemas or ``topics`` table.
    topics: dict[str, str] = field(default_factory=dict)
    #: type → (encoding, definition text), e.g. ``("ros2msg", "float64 x\n...")``: the
    #: MCAP schemas' data or the ``message_definitions`` table (empty ones left out).
    definitions: dict[str, tuple[str, str]] = field(default_factory=dict)
    problems: list[Problem] = field(default_factory=list)
    #: The file ends before its end (the recording was cut): said in ``problems``.
    truncated: bool = False

    def problem(self, where: str, issue: str, action: str, severity: Severity = "error") -> None:
        self.problems.append(Problem(self.file.name, where, issue, action, severity))

    def definition(self, msg_type: str, encoding: str, data: bytes | str, where: str) -> None:
        """Keep a type's definition (the first one; an empty one is no definition), or
        say why not."""
        size = len(data.encode("utf-8")) if isinstance(data, str) else len(data)
        if size == 0 or self.oversized(msg_type, size, where):
            return
        try:
            text = data if isinstance(data, str) else data.decode("utf-8")
        except UnicodeDecodeError as error:
            issue = f"definition of {msg_type} is not UTF-8: {error}"
            self.problem(where, issue, IGNORED_DEFINITION)
            return
        kept = self.definitions.setdefault(msg_type, (encoding, text))
        if kept != (encoding, text):
            issue = f"a second, different definition of {msg_type}"
            self.problem(where, issue, "the first one is used")

    def oversized(self, msg_type: str, size: int, where: str) -> bool:
        """A definition over :data:`MAX_DEFINITION_BYTES` is said and ignored."""
        if size <= MAX_DEFINITION_BYTES:
            return False
        issue = f"definition of {msg_type} has {size} bytes (limit {MAX_DEFINITION_BYTES})"
        self.problem(where, issue, IGNORED_DEFINITION)
        return True


@dataclass(frozen=True, slots=True)
class TopicCount:
    """How many messages a topic holds and the log times of its first and last (None when
    it has none with a usable time)."""

    count: int = 0
    first_ns: int | None = None
    last_ns: int | None = None

    def merged(self, other: TopicCount) -> TopicCount:
        """Both counts together (one topic split over several storage files)."""
        firsts = [t for t in (self.first_ns, other.first_ns) if t is not None]
        lasts = [t for t in (self.last_ns, other.last_ns) if t is not None]
        return TopicCount(
            self.count + other.count,
            min(firsts) if firsts else None,
            max(lasts) if lasts else None,
        )


#: How a listing's counts were found (said by ``inspect``).
LISTED_BY_SUMMARY = "the MCAP summary (statistics and message indexes)"
LISTED_BY_SCAN = "a scan of every record (no usable MCAP summary)"
LISTED_BY_SQL = "the sqlite3 topics and messages tables"
LISTED_BY_SALVAGE = "the rows a damaged sqlite3 file still yields"


@dataclass
class StorageListing(StorageRead):
    """What one storage file declares and how many messages each topic holds, the messages
    themselves not kept: ``inspect`` lists a bag of any size, whatever its types, without
    decoding or holding a message (``messages`` stays empty)."""

    #: topic name → its messages (every declared topic, 0 messages included)
    counts: dict[str, TopicCount] = field(default_factory=dict)
    #: how the counts were found (one of the ``LISTED_BY_*`` texts)
    method: str = ""


def counts_of(messages: Iterable[BagMessage]) -> dict[str, TopicCount]:
    """Per topic, the count and first and last log times of ``messages``."""
    found: dict[str, list[int]] = {}
    for message in messages:
        entry = found.get(message.topic)
        time = message.log_time_ns
        if entry is None:
            found[message.topic] = [1, time, time]
        else:
            entry[0] += 1
            entry[1] = min(entry[1], time)
            entry[2] = max(entry[2], time)
    return {topic: TopicCount(n, first, last) for topic, (n, first, last) in found.items()}


def list_storage(path: Path, expected_messages: int | None = None) -> StorageListing:
    """The topics, types, definitions and per-topic counts of a ``.mcap`` or ``.db3`` file,
    without keeping a message (see :class:`StorageListing`)."""
    if path.suffix == ".db3":
        return list_sqlite3(path, expected_messages)
    return list_mcap(path, expected_messages)


def read_storage(path: Path, expected_messages: int | None = None) -> StorageRead:
    """Every message a ``.mcap`` or ``.db3`` file still holds (``expected_messages``: what
    metadata.yaml announces, quoted when the file turns out to be cut)."""
    if path.suffix == ".db3":
        return read_sqlite3(path, expected_messages)
    return read_mcap(path, expected_messages)


# --- MCAP ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Stop:
    """Where and why an MCAP walk ended before the end magic."""

    section: str
    reason: str
    damaged_at: int | None = None  # None: the file is cut; else the damaged record's byte


class _McapWalk:
    """One pass over an MCAP file; fills a :class:`StorageRead`."""

    def __init__(self, path: Path, stream: BinaryIO, size: int) -> None:
        self.out = StorageRead(path)
        self.stream = stream
        self.size = size
        self.pos = len(MCAP_MAGIC)
        self.schemas: dict[int, str] = {0: ""}
        #: channel id → (topic, schema id, message encoding)
        self.channels: dict[int, tuple[str, int, str]] = {}
        self.unknown_channels: Counter[int] = Counter()
        self.foreign: Counter[str] = Counter()
        self.header = False

    # records ----------------------------------------------------------------------------

    def walk(self) -> _Stop | None:
        """Read records up to the end magic. None for a complete file, else why it stops."""
        section = "data section"
        while True:
            head = self.stream.read(_RECORD_HEAD)
            if len(head) < _RECORD_HEAD:
                missing = "summary and footer" if section == "data section" else "footer"
                return _Stop(section, f"it ends without {missing}")
            opcode, length = struct.unpack("<BQ", head)
            start = self.pos
            remaining = self.size - start - _RECORD_HEAD
            if opcode == 0:
                return _Stop(section, "invalid record (opcode 0)", damaged_at=start)
            if length > remaining:
                if opcode == _CHUNK:
                    self._partial_chunk(self.stream.read(remaining))
                return _Stop(section, f"the record at byte {start} is cut")
            body = self.stream.read(length)
            self.pos += _RECORD_HEAD + length
            try:
                self._record(opcode, body, start)
            except (CorruptRecord, struct.error, UnicodeDecodeError, ValueError) as error:
                return _Stop(section, f"damaged record: {error}", damaged_at=start)
            if opcode == _DATA_END:
                section = "summary"
            elif opcode == _FOOTER:
                if self.stream.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
                    return _Stop("footer", "the end magic is missing")
                return None

    def _record(self, opcode: int, body: bytes, offset: int) -> None:
        if opcode == _HEADER:
            self.header = True
        elif opcode == _SCHEMA:
            schema_id, name, encoding, data = _schema(body)
            if self.schemas.get(schema_id) == name:
                return  # the summary repeats the data section's schemas
            self.schemas[schema_id] = name
            where = f"schema {schema_id}"
            if data is None:
                self.out.problem(where, f"damaged data field ({name})", IGNORED_DEFINITION)
            elif schema_id != 0:
                self.out.definition(name, encoding, data, where)
        elif opcode == _CHANNEL:
            channel_id, topic, schema_id, encoding = _channel(body)
            self.channels.setdefault(channel_id, (topic, schema_id, encoding))
        elif opcode == _MESSAGE:
            self._message(body)
        elif opcode == _CHUNK:
            self._chunk(body, offset)

    def _message(self, body: bytes) -> None:
        if len(body) < _MESSAGE_HEAD:
            raise CorruptRecord("message record shorter than its header")
        channel_id, _seq, log_time, _pub = struct.unpack_from("<HIQQ", body)
        channel = self.channels.get(channel_id)
        if channel is None:
            self.unknown_channels[channel_id] += 1
            return
        topic, schema_id, encoding = channel
        if encoding != "cdr":
            self.foreign[topic] += 1
            return
        data = body[_MESSAGE_HEAD:]
        self.out.messages.append(
            BagMessage(
                topic, self.schemas.get(schema_id, ""), log_time, bytes(data), self.out.file.name
            )
        )

    # chunks -----------------------------------------------------------------------------

    def _chunk(self, body: bytes, offset: int) -> None:
        size, crc, compression, records = _chunk_fields(body, complete=True)
        where = f"chunk at byte {offset}"
        try:
            data = _decompress(compression, records, size)
        except CorruptRecord as error:
            self.out.problem(where, f"cannot be decompressed: {error}", SKIPPED_MESSAGES)
            return
        if crc and zlib.crc32(data) != crc:
            self.out.problem(
                where,
                "CRC mismatch: the chunk is damaged",
                "its messages are decoded one by one; undecodable ones are skipped",
            )
        try:
            self._inner(data, complete=True)
        except (CorruptRecord, struct.error, UnicodeDecodeError, ValueError) as error:
            self.out.problem(where, f"damaged: {error}", "the rest of the chunk skipped")

    def _partial_chunk(self, body: bytes) -> None:
        """A chunk cut by the end of the file: the complete messages before the cut.

        Sound because nothing is guessed: zstd and lz4 decoders emit only whole blocks, so
        what they give for a cut stream is exactly the start of what was written, and every
        inner record carries its length (a record reaching past the cut is dropped)."""
        try:
            size, _crc, compression, records = _chunk_fields(body, complete=False)
            self._inner(_decompress(compression, records, size, complete=False), complete=False)
        except (CorruptRecord, struct.error, UnicodeDecodeError, ValueError):
            return

    def _inner(self, data: bytes, complete: bool) -> None:
        """The records inside a chunk's (uncompressed) data."""
        pos = 0
        while pos < len(data):
            if len(data) - pos < _RECORD_HEAD:
                if complete:
                    raise CorruptRecord("a record header is cut")
                return
            opcode, length = struct.unpack_from("<BQ", data, pos)
            pos += _RECORD_HEAD
            if length > len(data) - pos:
                if complete:
                    raise CorruptRecord(f"a record claims {length} bytes, {len(data) - pos} remain")
                return
            self._record(opcode, data[pos : pos + length], -1)
            pos += length

    def recovered(self) -> int:
        """How many messages the walk kept (what a cut file is said to have given)."""
        return len(self.out.messages)

    def finish(self, stop: _Stop | None, expected: int | None) -> StorageRead:
        out = self.out
        for channel_id in sorted(self.unknown_channels):
            out.problem(
                f"channel {channel_id}",
                f"{self.unknown_channels[channel_id]} messages on a channel never defined",
                SKIPPED_MESSAGES,
            )
        for topic, n in sorted(self.foreign.items()):
            out.problem(topic, f"{n} messages not in CDR encoding", SKIPPED_MESSAGES)
        for topic, schema_id, _encoding in self.channels.values():
            out.topics.setdefault(topic, self.schemas.get(schema_id, ""))
        if stop is not None:
            out.truncated = True
            n = self.recovered()
            if stop.damaged_at is None:
                issue = truncation_issue(self.size, n, expected)
            else:
                issue = f"unreadable from byte {stop.damaged_at} on: {n} messages recovered"
            out.problem(stop.section, f"{issue} ({stop.reason})", KEPT_BEFORE_CUT)
        return out


def truncation_issue(at: int, recovered: int, expected: int | None) -> str:
    """The one wording of a cut file: where it ends, how many messages were kept."""
    of = f" of {expected} (metadata.yaml)" if expected is not None else ""
    return f"truncated after {at} bytes: {recovered}{of} messages recovered"


def _schema(body: bytes) -> tuple[int, str, str, bytes | None]:
    """Id, name, encoding and data of a schema record (data None when the record's
    encoding or data field is damaged: the name is still usable)."""
    (schema_id,) = struct.unpack_from("<H", body)
    name, pos = _string(body, 2)
    try:
        encoding, pos = _string(body, pos)
        (length,) = struct.unpack_from("<I", body, pos)
    except (CorruptRecord, struct.error, UnicodeDecodeError):
        return schema_id, name, "", None
    if pos + 4 + length > len(body):
        return schema_id, name, encoding, None
    return schema_id, name, encoding, body[pos + 4 : pos + 4 + length]


def _channel(body: bytes) -> tuple[int, str, int, str]:
    channel_id, schema_id = struct.unpack_from("<HH", body)
    topic, pos = _string(body, 4)
    encoding, _ = _string(body, pos)
    return channel_id, topic, schema_id, encoding


def _string(body: bytes, pos: int) -> tuple[str, int]:
    (length,) = struct.unpack_from("<I", body, pos)
    end = pos + 4 + length
    if end > len(body):
        raise CorruptRecord(f"a string claims {length} bytes, {len(body) - pos - 4} remain")
    return body[pos + 4 : end].decode("utf-8"), end


def _chunk_fields(body: bytes, complete: bool) -> tuple[int, int, str, bytes]:
    """Uncompressed size, CRC, compression and records bytes of a chunk record."""
    _start, _end, size, crc, clen = struct.unpack_from("<QQQII", body)
    pos = _CHUNK_HEAD
    if pos + clen + 8 > len(body):
        raise CorruptRecord("chunk header is cut")
    compression = body[pos : pos + clen].decode("utf-8")
    pos += clen
    (records_length,) = struct.unpack_from("<Q", body, pos)
    pos += 8
    records = body[pos : pos + records_length]
    if complete and len(records) != records_length:
        raise CorruptRecord(f"chunk data claims {records_length} bytes, {len(records)} remain")
    return size, crc, compression, records


def _decompress(compression: str, data: bytes, size: int, complete: bool = True) -> bytes:
    """A chunk's records, never more than its declared (and capped) size; ``complete``
    False: the start of a cut chunk (whatever its first bytes decode to)."""
    if size > MAX_CHUNK_BYTES:
        raise CorruptRecord(f"declares {size} uncompressed bytes (limit {MAX_CHUNK_BYTES})")
    if compression == "":
        return data
    try:
        if compression == "zstd":
            import zstandard

            with zstandard.ZstdDecompressor().stream_reader(data) as reader:
                out = _read_bounded(reader, size)
        elif compression == "lz4":
            import lz4.frame

            out = lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=size + 1)
        else:
            raise CorruptRecord(f"unknown compression {compression!r}")
    except (CorruptRecord, MemoryError):
        raise
    except Exception as error:  # zstd/lz4 report damage with their own error types
        raise CorruptRecord(f"{compression}: {error}") from error
    if complete and len(out) != size:
        raise CorruptRecord(f"{compression} data holds {len(out)} bytes, the chunk declares {size}")
    return out


class _Reader(Protocol):
    """A decompressing stream (zstandard's reader)."""

    def read(self, size: int = -1, /) -> bytes: ...


def _read_bounded(reader: _Reader, size: int) -> bytes:
    """At most ``size + 1`` bytes, read in pieces (memory follows the real data)."""
    parts: list[bytes] = []
    total = 0
    while total <= size:
        piece = reader.read(min(1 << 20, size + 1 - total))
        if not piece:
            break
        parts.append(piece)
        total += len(piece)
    return b"".join(parts)


def open_storage(path: Path) -> BinaryIO:
    """``path`` opened if it is a regular file; InputError naming why not."""
    stream = open_regular(path)
    if isinstance(stream, Unreadable):
        raise InputError(f"{path}: {stream.issue}")
    return stream


def read_mcap(path: Path, expected_messages: int | None = None) -> StorageRead:
    """Every message an MCAP file holds, up to where it is cut or damaged (see module doc)."""
    with open_storage(path) as stream:
        size = os.fstat(stream.fileno()).st_size
        magic = stream.read(len(MCAP_MAGIC))
        if magic != MCAP_MAGIC:
            raise InputError(
                f"{path}: not an MCAP file, or truncated before the first record ({size} bytes)"
            )
        walk = _McapWalk(path, stream, size)
        stop = walk.walk()
    if not walk.header:
        raise InputError(f"{path}: truncated before the first record ({size} bytes)")
    return walk.finish(stop, expected_messages)


# --- MCAP listing --------------------------------------------------------------------------

_MESSAGE_INDEX, _CHUNK_INDEX, _STATISTICS = 7, 8, 11
_FOOTER_RECORD = _RECORD_HEAD + 8 + 8 + 4  # summary start, summary offset start, CRC
#: Largest summary section read whole; a larger one (or a damaged length) is scanned past.
MAX_SUMMARY_BYTES = 1 << 28


class _McapCount(_McapWalk):
    """An MCAP walk that counts each channel's messages and their first and last log times
    instead of keeping them: the listing of a file without a usable summary."""

    def __init__(self, path: Path, stream: BinaryIO, size: int) -> None:
        super().__init__(path, stream, size)
        self.listing = StorageListing(path, method=LISTED_BY_SCAN)
        self.out = self.listing
        #: channel id → [count, first log time, last log time]
        self.counts: dict[int, list[int]] = {}

    def _message(self, body: bytes) -> None:
        if len(body) < _MESSAGE_HEAD:
            raise CorruptRecord("message record shorter than its header")
        channel_id, _seq, log_time, _pub = struct.unpack_from("<HIQQ", body)
        if channel_id not in self.channels:
            self.unknown_channels[channel_id] += 1
            return
        entry = self.counts.get(channel_id)
        if entry is None:
            self.counts[channel_id] = [1, log_time, log_time]
        else:
            entry[0] += 1
            entry[1] = min(entry[1], log_time)
            entry[2] = max(entry[2], log_time)

    def recovered(self) -> int:
        return sum(entry[0] for entry in self.counts.values())

    def listed(self, stop: _Stop | None, expected: int | None) -> StorageListing:
        """The listing, every channel's topic counted (0 for a channel without messages)."""
        self.finish(stop, expected)
        by_channel = {cid: TopicCount(*entry) for cid, entry in self.counts.items()}
        _count_channels(self.listing, self.channels, by_channel)
        return self.listing


def _count_channels(
    out: StorageListing,
    channels: dict[int, tuple[str, int, str]],
    by_channel: dict[int, TopicCount],
) -> None:
    """``out.counts`` per topic from per-channel counts (channels of one topic summed)."""
    for channel_id, (topic, _schema_id, _encoding) in sorted(channels.items()):
        count = by_channel.get(channel_id, TopicCount())
        out.counts[topic] = out.counts.get(topic, TopicCount()).merged(count)


def list_mcap(path: Path, expected_messages: int | None = None) -> StorageListing:
    """An MCAP file's listing: from its summary (statistics, then each chunk's message
    indexes for the times: no chunk is decompressed) when it has a consistent one, else
    from a walk of every record (a recording cut before its summary, or written without)."""
    with open_storage(path) as stream:
        size = os.fstat(stream.fileno()).st_size
        if stream.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            raise InputError(
                f"{path}: not an MCAP file, or truncated before the first record ({size} bytes)"
            )
        summary = _summary_listing(path, stream, size)
        if summary is not None:
            return summary
        stream.seek(len(MCAP_MAGIC))
        walk = _McapCount(path, stream, size)
        stop = walk.walk()
    if not walk.header:
        raise InputError(f"{path}: truncated before the first record ({size} bytes)")
    return walk.listed(stop, expected_messages)


@dataclass
class _Summary:
    """What an MCAP summary section says (the parts a listing needs)."""

    schemas: dict[int, str] = field(default_factory=lambda: {0: ""})
    channels: dict[int, tuple[str, int, str]] = field(default_factory=dict)
    #: total messages and per-channel counts, when the file has a statistics record
    total: int | None = None
    channel_counts: dict[int, int] | None = None
    #: per chunk: (message index records' start, their length)
    indexes: list[tuple[int, int]] = field(default_factory=list)


def _summary_listing(path: Path, stream: BinaryIO, size: int) -> StorageListing | None:
    """The listing the summary gives, or None when it cannot be trusted to be complete
    (no footer, no summary, damaged, or counts that its message indexes do not add up
    to): the caller then walks the file."""
    footer_at = size - len(MCAP_MAGIC) - _FOOTER_RECORD
    if footer_at < len(MCAP_MAGIC):
        return None
    stream.seek(footer_at)
    tail = stream.read(_FOOTER_RECORD + len(MCAP_MAGIC))
    if len(tail) != _FOOTER_RECORD + len(MCAP_MAGIC) or tail[-len(MCAP_MAGIC) :] != MCAP_MAGIC:
        return None
    opcode, length, start, _offsets, _crc = struct.unpack_from("<BQQQI", tail)
    if opcode != _FOOTER or length != _FOOTER_RECORD - _RECORD_HEAD:
        return None
    if not len(MCAP_MAGIC) < start < footer_at or footer_at - start > MAX_SUMMARY_BYTES:
        return None
    stream.seek(start)
    out = StorageListing(path, method=LISTED_BY_SUMMARY)
    try:
        summary = _summary(stream.read(footer_at - start), out)
        if summary is None:
            return None
        by_channel = _indexed_counts(stream, summary, start)
    except (CorruptRecord, struct.error, UnicodeDecodeError, ValueError):
        return None
    if by_channel is None:
        return None
    for _channel_id, (topic, schema_id, _encoding) in sorted(summary.channels.items()):
        out.topics.setdefault(topic, summary.schemas[schema_id])
    _count_channels(out, summary.channels, by_channel)
    return out


def _summary(data: bytes, out: StorageListing) -> _Summary | None:
    """The summary section's schemas (their definitions kept in ``out``), channels,
    statistics and chunk indexes; None when a channel names a schema it does not hold."""
    found = _Summary()
    pos = 0
    while pos < len(data):
        opcode, length = struct.unpack_from("<BQ", data, pos)
        pos += _RECORD_HEAD
        if length > len(data) - pos:
            raise CorruptRecord(f"a summary record claims {length} bytes")
        body = data[pos : pos + length]
        pos += length
        if opcode == _SCHEMA:
            schema_id, name, encoding, text = _schema(body)
            found.schemas[schema_id] = name
            if text is not None and schema_id != 0:
                out.definition(name, encoding, text, f"schema {schema_id}")
        elif opcode == _CHANNEL:
            channel_id, topic, schema_id, encoding = _channel(body)
            found.channels.setdefault(channel_id, (topic, schema_id, encoding))
        elif opcode == _STATISTICS:
            found.total, found.channel_counts = _statistics(body)
        elif opcode == _CHUNK_INDEX:
            found.indexes.append(_chunk_index(body))
    if any(schema_id not in found.schemas for _t, schema_id, _e in found.channels.values()):
        return None
    return found


def _statistics(body: bytes) -> tuple[int, dict[int, int]]:
    """A statistics record's message count and per-channel counts."""
    (total,) = struct.unpack_from("<Q", body)
    pos = 8 + 2 + 4 * 4 + 8 + 8  # the schema, channel, ... counts and the message times
    return total, dict(_map16(body, pos)[0])


def _chunk_index(body: bytes) -> tuple[int, int]:
    """Where a chunk's message index records are: (their first byte, their length)."""
    _first, _last, chunk_start, chunk_length = struct.unpack_from("<QQQQ", body)
    _offsets, pos = _map16(body, 32)
    (index_length,) = struct.unpack_from("<Q", body, pos)
    return chunk_start + chunk_length, index_length


def _map16(body: bytes, pos: int) -> tuple[list[tuple[int, int]], int]:
    """An MCAP ``map<uint16, uint64>`` at ``pos``: its entries and the position after it."""
    (length,) = struct.unpack_from("<I", body, pos)
    pos += 4
    if length % 10 or pos + length > len(body):
        raise CorruptRecord(f"a map claims {length} bytes")
    entries = [struct.unpack_from("<HQ", body, at) for at in range(pos, pos + length, 10)]
    return entries, pos + length


def _indexed_counts(
    stream: BinaryIO, summary: _Summary, summary_start: int
) -> dict[int, TopicCount] | None:
    """Per channel, its messages from the chunks' message index records (a log time and
    an offset per message: 16 bytes each, no chunk decompressed); None unless they add up
    to the statistics (a file written without indexes, or messages outside chunks)."""
    found: dict[int, TopicCount] = {}
    for index_start, index_length in summary.indexes:
        if not len(MCAP_MAGIC) <= index_start <= summary_start - index_length:
            return None
        stream.seek(index_start)
        data = stream.read(index_length)
        pos = 0
        while pos < len(data):
            opcode, length = struct.unpack_from("<BQ", data, pos)
            pos += _RECORD_HEAD
            if length > len(data) - pos:
                return None
            if opcode == _MESSAGE_INDEX:
                channel_id, times = _message_index(data[pos : pos + length])
                if times.size:
                    seen = TopicCount(int(times.size), int(times.min()), int(times.max()))
                    found[channel_id] = found.get(channel_id, TopicCount()).merged(seen)
            pos += length
    total = sum(count.count for count in found.values())
    if summary.total is None:
        return found if summary.indexes else None
    if total != summary.total or not set(found) <= set(summary.channels):
        return None
    if summary.channel_counts is not None and any(
        found.get(cid, TopicCount()).count != n for cid, n in summary.channel_counts.items()
    ):
        return None
    return found


def _message_index(body: bytes) -> tuple[int, npt.NDArray[np.uint64]]:
    """A message index record's channel and the log times of its messages."""
    (channel_id, length) = struct.unpack_from("<HI", body)
    if length % 16 or 6 + length > len(body):
        raise CorruptRecord(f"a message index claims {length} bytes")
    pairs = np.frombuffer(body, dtype="<u8", count=length // 8, offset=6)
    return channel_id, pairs[0::2]


# --- sqlite3 -------------------------------------------------------------------------------


def read_sqlite3(path: Path, expected_messages: int | None = None) -> StorageRead:
    """Every row a rosbag2 sqlite3 file still yields (read-only, in row order).

    sqlite refuses a file shorter than its header announces ("malformed"); such a cut file
    is read from a private copy of its whole pages with the header's page count set to
    them, so the tables and rows stored before the cut are still found."""
    out = StorageRead(path)
    with open_storage(path) as stream:
        size = os.fstat(stream.fileno()).st_size
        announced = _sqlite_size(stream.read(100))
        if announced is None or size >= announced:
            damage = _sqlite_rows(_descriptor_path(stream, path), path, out)
        else:
            with tempfile.TemporaryDirectory(prefix="ads_rca_db3_") as private:
                stream.seek(0)
                try:
                    damage = _sqlite_rows(_whole_pages(path, stream, Path(private)), path, out)
                except InputError as error:
                    cut = f"truncated after {size} of {announced} bytes"
                    raise InputError(f"{error} ({cut})") from None
    if announced is not None and size < announced:
        out.truncated = True
        out.problem(
            "database",
            truncation_issue(size, len(out.messages), expected_messages)
            + f" (the header announces {announced} bytes"
            + (f"; {damage}" if damage else "")
            + ")",
            KEPT_BEFORE_CUT,
        )
        return out
    if damage is not None:
        out.truncated = True
        out.problem(
            "messages",
            f"damaged after {len(out.messages)} messages ({damage}): "
            f"{len(out.messages)} messages recovered",
            KEPT_BEFORE_CUT,
        )
    return out


def _sqlite_rows(database: Path, path: Path, out: StorageRead) -> str | None:
    """Fill ``out`` from ``database`` (``path``: the bag's file, for names); returns the
    damage that stopped the rows, if any. InputError when not even the topics are readable."""
    connection = _connect(database, path)
    by_id: dict[int, tuple[str, str]] = {}
    foreign: Counter[str] = Counter()
    unknown = 0
    damage: str | None = None
    try:
        try:
            rows = connection.execute("SELECT id, name, type, serialization_format FROM topics")
            topic_rows = rows.fetchall()
        except sqlite3.Error as error:
            raise InputError(f"{path}: not a readable rosbag2 sqlite3 file: {error}") from error
        for topic_id, name, msg_type, encoding in topic_rows:
            by_id[int(topic_id)] = (str(name), str(msg_type))
            out.topics.setdefault(str(name), str(msg_type))
            if encoding != "cdr":
                foreign[str(name)] = 0
        _sqlite_definitions(connection, out)
        try:
            cursor = connection.execute("SELECT topic_id, timestamp, data FROM messages")
            for topic_id, timestamp, data in cursor:
                entry = by_id.get(int(topic_id))
                if entry is None:
                    unknown += 1
                elif entry[0] in foreign:
                    foreign[entry[0]] += 1
                else:
                    out.messages.append(
                        BagMessage(entry[0], entry[1], int(timestamp), bytes(data), path.name)
                    )
        except (sqlite3.Error, TypeError, ValueError) as error:
            damage = str(error)
    finally:
        connection.close()
    if unknown:
        out.problem("messages", f"{unknown} messages on a topic id never defined", SKIPPED_MESSAGES)
    for topic, n in sorted(foreign.items()):
        out.problem(topic, f"{n} messages not in CDR encoding", SKIPPED_MESSAGES)
    return damage


def _connect(database: Path, path: Path) -> sqlite3.Connection:
    """A read-only (immutable) connection to ``database`` (``path`` names it in errors)."""
    uri = f"{Path(os.path.abspath(database)).as_uri()}?immutable=1"  # no resolve: /proc
    try:
        return sqlite3.connect(uri, uri=True)
    except sqlite3.Error as error:
        raise InputError(f"{path}: cannot open the sqlite3 bag: {error}") from error


#: Per topic id: its messages, the first and last integer log times, and how many rows
#: have a log time that is no integer (a damaged or hostile file).
_COUNT_MESSAGES = """
SELECT topic_id, COUNT(*),
       MIN(CASE WHEN typeof(timestamp) = 'integer' THEN timestamp END),
       MAX(CASE WHEN typeof(timestamp) = 'integer' THEN timestamp END),
       SUM(typeof(timestamp) != 'integer')
FROM messages GROUP BY topic_id
"""


def list_sqlite3(path: Path, expected_messages: int | None = None) -> StorageListing:
    """A rosbag2 sqlite3 file's listing: topics and types from its ``topics`` table,
    definitions from ``message_definitions`` when it has one (a bag recorded before Iron
    has none: nothing needs them to list), per-topic counts and times counted by sqlite
    (no message is fetched). A file cut short or damaged inside ``messages`` is listed
    from the rows :func:`read_sqlite3` still salvages, its damage said."""
    with open_storage(path) as stream:
        size = os.fstat(stream.fileno()).st_size
        announced = _sqlite_size(stream.read(100))
        if announced is None or size >= announced:
            listing = _sqlite_counted(_descriptor_path(stream, path), path)
            if listing is not None:
                return listing
    read = read_sqlite3(path, expected_messages)
    out = StorageListing(
        path,
        topics=read.topics,
        definitions=read.definitions,
        problems=read.problems,
        truncated=read.truncated,
        method=LISTED_BY_SALVAGE,
    )
    counted = counts_of(read.messages)
    out.counts = {name: counted.get(name, TopicCount()) for name in read.topics}
    return out


def _sqlite_counted(database: Path, path: Path) -> StorageListing | None:
    """The listing sqlite's own count gives; None when the messages table is damaged (the
    caller salvages row by row). InputError when not even the topics are readable."""
    out = StorageListing(path, method=LISTED_BY_SQL)
    connection = _connect(database, path)
    # Names are listed even when not UTF-8 (shown with U+FFFD): a listing never refuses
    # a bag for one bad byte in a name.
    connection.text_factory = lambda raw: raw.decode("utf-8", "replace")
    try:
        try:
            rows = connection.execute("SELECT id, name, type FROM topics").fetchall()
        except sqlite3.Error as error:
            raise InputError(f"{path}: not a readable rosbag2 sqlite3 file: {error}") from error
        by_id: dict[int, str] = {}
        for topic_id, name, msg_type in rows:
            if not isinstance(topic_id, int):
                out.problem("topics", f"a topic id {short_repr(topic_id)} is no integer", IGNORED)
                continue
            by_id[topic_id] = str(name)
            if out.topics.setdefault(str(name), str(msg_type)) != str(msg_type):
                out.problem(
                    "topics", f"{str(name)!r} declared again as {msg_type}", "the first type used"
                )
        _sqlite_definitions(connection, out)
        try:
            counted = connection.execute(_COUNT_MESSAGES).fetchall()
        except sqlite3.Error:
            return None
    finally:
        connection.close()
    out.counts = dict.fromkeys(out.topics, TopicCount())
    unknown = untimed = 0
    for topic_id, count, first, last, no_time in counted:
        name = by_id.get(topic_id) if isinstance(topic_id, int) else None
        if name is None:
            unknown += int(count)
            continue
        untimed += int(no_time or 0)
        out.counts[name] = out.counts[name].merged(TopicCount(int(count), first, last))
    if unknown:
        out.problem("messages", f"{unknown} messages on a topic id never defined", IGNORED)
    if untimed:
        out.problem("messages", f"{untimed} messages with a timestamp that is no integer", IGNORED)
    return out


def _sqlite_definitions(connection: sqlite3.Connection, out: StorageRead) -> None:
    """The ``message_definitions`` table (rosbag2 >= Iron) into ``out``; an older bag has
    none. A definition over the limit is measured by sqlite, never fetched."""
    size = "length(CAST(encoded_message_definition AS BLOB))"
    query = (
        f"SELECT topic_type, encoding, CASE WHEN {size} <= ? THEN encoded_message_definition"
        f" END, {size} FROM message_definitions ORDER BY id"
    )
    try:
        rows = connection.execute(query, (MAX_DEFINITION_BYTES,)).fetchall()
    except sqlite3.Error as error:
        if "no such table" not in str(error):
            out.problem("message_definitions", f"unreadable: {error}", "no definition read")
        return
    for msg_type, encoding, text, length in rows:
        if isinstance(length, int) and out.oversized(str(msg_type), length, "message_definitions"):
            continue
        data = text if isinstance(text, (str, bytes)) else ""
        out.definition(str(msg_type), str(encoding), data, "message_definitions")


def _descriptor_path(stream: BinaryIO, path: Path) -> Path:
    """A name that opens exactly the checked file behind ``stream`` (Linux's
    ``/proc/self/fd``), else ``path`` itself."""
    proc = Path(f"/proc/self/fd/{stream.fileno()}")
    return proc if proc.exists() else path


def _whole_pages(path: Path, source: BinaryIO, directory: Path) -> Path:
    """A copy of the whole pages of a cut sqlite file (read from ``source``), its header's
    page count set to them (copied on disk, not through memory: a bag can be large)."""
    copy = directory / path.name
    with copy.open("wb") as out:
        shutil.copyfileobj(source, out)
    with copy.open("r+b") as stream:
        (page_size,) = struct.unpack(">H", stream.read(18)[16:18])
        page_size = 65536 if page_size == 1 else page_size
        pages = os.fstat(stream.fileno()).st_size // page_size
        if pages == 0:
            raise InputError(f"{path}: cut inside its first page")
        stream.truncate(pages * page_size)
        stream.seek(28)
        stream.write(struct.pack(">I", pages))
    return copy


def _sqlite_size(header: bytes) -> int | None:
    """The database size its first 100 bytes announce (pages × page size), or None if
    unknown."""
    if len(header) < 100 or not header.startswith(b"SQLite format 3\x00"):
        return None
    (page_size,) = struct.unpack_from(">H", header, 16)
    page_size = 65536 if page_size == 1 else page_size
    change, pages = struct.unpack_from(">II", header, 24)
    (valid_for,) = struct.unpack_from(">I", header, 92)
    if pages == 0 or change != valid_for:  # the in-header size is only valid when these agree
        return None
    return int(pages) * int(page_size)
