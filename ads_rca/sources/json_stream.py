"""The members of a huge top-level JSON object, one at a time, in bounded memory.

A dataset's file can be one JSON object of over a million members (a drone-recorded scene's
instances: hundreds of MB): loading it whole costs gigabytes of Python objects.
:func:`object_members` reads it in 1 MB chunks and parses one ``"key": value`` member at a
time with the standard library's C scanner (``JSONDecoder.raw_decode``), so memory holds
one chunk and one member. A member larger than ``max_member`` bytes, invalid JSON or a cut
file raises :class:`InvalidJson` naming the character where it stopped; the members yielded
before it stand (the caller keeps them).
"""

from __future__ import annotations

import codecs
import json
from collections.abc import Iterator
from typing import Any, BinaryIO

from ads_rca.sources.errors import InvalidJson

CHUNK = 1 << 20
_WHITESPACE = " \t\n\r"
_DECODER = json.JSONDecoder()


class _Buffer:
    """Decoded text of a stream, refilled a chunk at a time; ``pos`` is the read point."""

    def __init__(self, stream: BinaryIO, max_member: int) -> None:
        self.stream = stream
        self.decoder = codecs.getincrementaldecoder("utf-8")()
        self.text = ""
        self.pos = 0
        self.eof = False
        self.consumed = 0  # characters dropped from the front (for offsets)
        self.max_member = max_member

    def fill(self) -> bool:
        """More text at the end; False at the end of the stream."""
        if self.eof:
            return False
        if len(self.text) - self.pos > self.max_member:
            raise InvalidJson(
                f"a member of more than {self.max_member} bytes at character {self.offset}"
            )
        data = self.stream.read(CHUNK)
        self.eof = not data
        try:
            more = self.decoder.decode(data, final=self.eof)
        except UnicodeDecodeError as error:
            raise InvalidJson(f"not UTF-8 near character {self.offset}: {error.reason}") from None
        self.consumed += self.pos
        self.text = self.text[self.pos :] + more
        self.pos = 0
        return True

    @property
    def offset(self) -> int:
        return self.consumed + self.pos

    def skip_space(self) -> str:
        """The next non-space character ("" at the end), not consumed."""
        while True:
            text, pos = self.text, self.pos
            while pos < len(text) and text[pos] in _WHITESPACE:
                pos += 1
            self.pos = pos
            if pos < len(text):
                return text[pos]
            if not self.fill():
                return ""

    def expect(self, characters: str, what: str) -> str:
        found = self.skip_space()
        if not found or found not in characters:
            shown = repr(found) if found else "the end of the file"
            raise InvalidJson(f"expected {what} at character {self.offset}, found {shown}")
        self.pos += 1
        return found

    def value(self) -> Any:
        """The JSON value at the read point (more text read until it is whole)."""
        self.skip_space()
        while True:
            try:
                value, end = _DECODER.raw_decode(self.text, self.pos)
            except json.JSONDecodeError as error:
                if self.fill():
                    continue
                raise InvalidJson(f"{error.msg} (character {self.consumed + error.pos})") from None
            except RecursionError:
                raise InvalidJson(f"nested too deep at character {self.offset}") from None
            # A number (or literal) ending the text may go on in the next chunk.
            if end == len(self.text) and not self.eof and self.fill():
                continue
            self.pos = end
            return value


def object_members(stream: BinaryIO, max_member: int) -> Iterator[tuple[str, Any]]:
    """Each ``(key, value)`` of the JSON object ``stream`` holds, in file order."""
    buffer = _Buffer(stream, max_member)
    buffer.expect("{", "an object")
    if buffer.skip_space() == "}":
        buffer.pos += 1
    else:
        while True:
            if buffer.skip_space() != '"':
                buffer.expect('"', "a member name")
            key = buffer.value()
            buffer.expect(":", "':'")
            yield key, buffer.value()
            if buffer.expect(",}", "',' or '}'") == "}":
                break
    if buffer.skip_space():
        raise InvalidJson(f"text after the object at character {buffer.offset}")
