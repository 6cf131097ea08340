"""``json.dumps(document, indent=1)``'s exact text, at orjson's speed.

The verdict JSON of a long run is megabytes of indented text, and the json module indents
in pure Python (about 1 s for 10,000 frames of 50 actors). orjson writes it in C, but
indents by two spaces, spells small floats its own way and leaves non-ASCII text as it is.
This takes orjson's text and undoes exactly those three differences, so that the bytes are
the json module's (tests compare the two on random documents):

- indentation halved: every line's leading spaces are indentation (a JSON string holds no
  raw newline);
- floats below 1e-4 spelled as Python spells them (``1e-05``, not ``0.00001``; ``1e-07``,
  not ``1e-7``); the digits are the same (both write the shortest text that reads back to
  the same float), so the float is read back and written with ``repr``;
- DEL and every non-ASCII character escaped as ``\\uXXXX`` (surrogate pairs beyond the
  BMP), as ``ensure_ascii`` does.

An object's long values (a verdict's frames and ``$nonfinite`` map) are converted a batch of
items at a time, so the text is written piece by piece, never held whole
(``bench/bench_verdict_json.py``); a :class:`RenderedList` (the frames made while they
were judged) is held as its text instead of as a document, a fraction of its size.
What orjson refuses (integers beyond 64 bits, non-string keys, numpy values, lone
surrogates) is written by the json module. The document must be strict already
(:func:`ads_rca.foundation.strictjson.to_strict`): orjson writes NaN and infinity as ``null``.
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from typing import Any, TextIO

import numpy as np
import orjson

from ads_rca.foundation.strictjson import NonFinite, StrictValue, strict_items

#: Items of a long top-level value converted at a time: bounds the text held at once.
BATCH_ITEMS = 250
_NEWLINE, _SPACE = 0x0A, 0x20
#: Where orjson and Python spell a float differently: ``0.0000…`` and a one-digit exponent.
#: Two patterns, each led by a literal that the regex engine searches for at memchr speed
#: (their alternation is scanned a byte at a time: four times as long on a verdict). They
#: never overlap (neither holds the other's first byte), so their matches together are
#: those of the alternation.
_SMALL_FLOATS = (re.compile(rb"0\.0000"), re.compile(rb"e-[1-4](?![0-9])"))
#: A one-digit negative exponent of 5 or more ending a token that ends its line: below
#: 1e-4 Python writes the same digits with a two-digit exponent (``e-06``), so a zero is
#: put in, in C. A match ends its line, so it is no string's (whose quote would end the
#: line) and no key's: its token is a number (no other bare token holds "e-"). Led by a
#: literal, as the patterns above.
_EXPONENT_FROM_5 = re.compile(rb"e-([5-9])(?=\n|,\n|\Z)")
_NUMBER_BYTES = frozenset(b"0123456789.-+eE")
#: Every character past ``~``: the negated class compiles in 0.05 ms, its range twin
#: (``[\x7f-\U0010ffff]``) in 3 ms at every start-up.
_ESCAPED = re.compile("[^\x00-\x7e]")


def dumps_indented(document: Any) -> str:
    """``json.dumps(document, indent=1, allow_nan=False)`` of a strict document."""
    return "".join(iter_indented(document))


def write_indented(document: Any, out: TextIO) -> None:
    """:func:`dumps_indented` written piece by piece."""
    for piece in iter_indented(document):
        out.write(piece)


def iter_indented(document: Any, batch_items: int = BATCH_ITEMS) -> Iterator[str]:
    """The text of :func:`dumps_indented`, in consecutive pieces.

    A long top-level value of an object (a verdict's frames, its ``$nonfinite`` map) is
    converted ``batch_items`` items at a time, so the text of a long run is never held whole
    beside the document.
    """
    if not (isinstance(document, dict) and document and all(type(k) is str for k in document)):
        yield _text(document)
        return
    yield "{"
    for index, (key, value) in enumerate(document.items()):
        yield f"{',' if index else ''}\n {json.dumps(key)}: "
        if isinstance(value, RenderedList):
            yield from value.pieces()
        elif isinstance(value, list | dict) and len(value) > batch_items:
            yield from _in_batches(value, batch_items)
        else:
            yield _text(value).replace("\n", "\n ")
    yield "\n}"


def _in_batches(value: list[Any] | dict[Any, Any], batch_items: int) -> Iterator[str]:
    """A long list or object one level down, ``batch_items`` items at a time."""
    items: list[Any] = value if isinstance(value, list) else list(value.items())
    as_list = items is value
    yield "[" if as_list else "{"
    for start in range(0, len(items), batch_items):
        part = items[start : start + batch_items]
        yield _items_text(part if as_list else dict(part), bool(start))
    yield "\n ]" if as_list else "\n }"


def _items_text(part: list[Any] | dict[str, Any], after: bool) -> str:
    """Consecutive items of a long value one level down, as they are written there
    (``after`` items before them: a comma first)."""
    body = _text(part)[2:-2]  # without the bracket lines
    return ("," if after else "") + "\n " + body.replace("\n", "\n ")


class RenderedList(StrictValue):
    """A long list value of a top-level key (a verdict's frames), made strict and
    written as :func:`iter_indented` writes such a list, part by part as its items come.

    Why: the frames of a long run are judged in forked workers, and their text made after
    the judging took a tenth of a diagnosis with one core idle; made in the parent as each
    slice comes back, it takes the time the workers leave free. ``to_strict`` takes it as
    it is (its pointers were found as it was made), ``len()`` is its item count.
    """

    def __init__(self, key: str) -> None:
        self.key = key
        self.count = 0
        self.nonfinite: NonFinite = []
        self._parts: list[str] = []

    def __len__(self) -> int:
        return self.count

    def extend(self, items: list[Any]) -> None:
        """The next items (strict copies are made of them, their non-finite pointers kept)."""
        if not items:
            return
        plain, found = strict_items(items, self.key, self.count)
        self._parts.append(_items_text(plain, bool(self.count)))
        self.nonfinite.extend(found)
        self.count += len(items)

    def pieces(self) -> Iterator[str]:
        """The list's text, one level down in its document."""
        if not self.count:
            yield "[]"
            return
        yield "["
        yield from self._parts
        yield "\n ]"


def _text(value: Any) -> str:
    """The json module's indented text of ``value``, from orjson's where orjson can."""
    try:
        raw = orjson.dumps(value, option=orjson.OPT_INDENT_2)
    except TypeError:  # beyond orjson: the json module writes it (slowly, but the same)
        return json.dumps(value, indent=1, allow_nan=False)
    text = _respell_small_floats(_halve_indentation(raw)).decode("utf-8")
    if text.isascii() and "\x7f" not in text:
        return text
    return _ESCAPED.sub(_escape, text)


def _halve_indentation(block: bytes) -> bytes:
    """Each line's leading spaces halved (2 per level -> 1), with array operations."""
    data = np.frombuffer(block, dtype=np.uint8)
    starts = np.concatenate(([0], np.flatnonzero(data == _NEWLINE) + 1))
    starts = starts[starts < data.size]
    space = data == _SPACE
    run_ends = np.flatnonzero(space[:-1] & ~space[1:]) + 1  # where runs of spaces end
    at_run = space[starts]
    width = np.zeros(starts.size, dtype=np.int64)
    width[at_run] = run_ends[np.searchsorted(run_ends, starts[at_run])] - starts[at_run]
    keep = np.ones(data.size, dtype=bool)
    half = width // 2
    for level in range(int(half.max(initial=0))):  # the first half of each indentation
        keep[starts[half > level] + level] = False
    return data[keep].tobytes()


def _respell_small_floats(block: bytes) -> bytes:
    """Number tokens that orjson spells unlike Python, respelled with ``repr``.

    A candidate counts only as a whole number token that ends its line (before an optional
    comma) and follows a space or a line start: a string's closing quote would come before
    the end of its line, so such a token is never inside a string. The most frequent kind,
    an exponent of -5 or below written with one digit, gets its zero in one C pass
    (:data:`_EXPONENT_FROM_5`): five in six candidates of a corrected verdict, whose
    respelling took a third of its writing.
    """
    if b"0.0000" not in block and b"e-" not in block:
        return block
    block = _EXPONENT_FROM_5.sub(rb"e-0\1", block)
    pieces: list[bytes] = []
    done = 0
    for span in sorted(m.span() for p in _SMALL_FLOATS for m in p.finditer(block)):
        start, end = span
        if start < done:
            continue
        while start > 0 and block[start - 1] in _NUMBER_BYTES:
            start -= 1
        while end < len(block) and block[end] in _NUMBER_BYTES:
            end += 1
        before = block[start - 1 : start] if start else b"\n"
        after = block[end : end + 2]
        if before not in (b" ", b"\n") or not _ends_line(after, end == len(block)):
            continue
        try:
            respelled = repr(float(block[start:end])).encode()
        except ValueError:
            continue
        pieces += [block[done:start], respelled]
        done = end
    if not pieces:
        return block
    pieces.append(block[done:])
    return b"".join(pieces)


def _ends_line(after: bytes, at_end: bool) -> bool:
    return at_end or after[:1] == b"\n" or after == b",\n"


def _escape(match: re.Match[str]) -> str:
    code = ord(match.group())
    if code <= 0xFFFF:
        return f"\\u{code:04x}"
    code -= 0x10000
    return f"\\u{0xD800 | (code >> 10):04x}\\u{0xDC00 | (code & 0x3FF):04x}"
