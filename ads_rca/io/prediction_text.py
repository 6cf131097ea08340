"""A predictions file's numbers read from its text, without making its objects.

A predictions file is dozens of tracks of dozens of steps, each step an object of three
numbers: decoded as JSON, a dict per step and a dict per track, then taken apart again into
one array. That is most of the cost of reading a long log (four fifths of its bytes are
predictions). This reads the common layout in two passes over the bytes, each a C loop:

- **numbers**: braces, quotes, colons and the step keys' letters dropped, ``{`` turned into
  ``,``, so ``{"7":{"0":{"x":1.5,"y":2,"z":0.0}}}`` becomes the flat JSON array
  ``[7,0,1.5,2,0.0]``: orjson parses its numbers (the same parser and number text as the
  whole file's) without making one container;
- **layout**: digits deleted and every other number character (and whitespace) turned
  into ``#``; once the ``#`` are gone, the text must equal exactly the layout of ``n``
  tracks of ``k`` steps ``{"":{"":{"x":,"y":,"z":},...},...}`` that those numbers imply.
  A ``#`` just after an opening quote is a key that is not a plain non-negative integer
  (``"-0"``, ``"1.5"``, ``" 7"``), whose text its number would not give back.

Anything else (another layout or key order, a missing ``z``, strings for numbers, ``NaN``,
duplicate keys, tracks of different step keys or none, whitespace inside a key or before a
colon...) returns None, and the file is decoded and parsed as any other, which says what is
wrong. So the result, when there is one, is what :func:`~ads_rca.io.records.prediction_parts`
gives for the decoded file (tests compare the two on clean and hostile files).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import orjson

from ads_rca.io.records import PredictionParts

#: Numbers pass: ``{`` separates like a comma; quotes, colons, ``}`` and x/y/z go.
_NUMBERS_TABLE = bytes.maketrans(b"{", b",")
_NUMBERS_DROPPED = b'":}xyz'
#: Layout pass: digits go, the other number characters and whitespace become ``#``.
_LAYOUT_TABLE = bytes.maketrans(b"-+.eE \t\n\r", b"#########")
_DIGITS = b"0123456789"
_MARK = b"#"
#: Keys are compared as float64: exact below 2**53 (a larger integer key falls back).
_EXACT_INTEGERS = 2.0**53


def prediction_parts_from_text(data: bytes) -> PredictionParts | None:
    """The :data:`~ads_rca.io.records.PredictionParts` of a predictions file's ``data`` in
    the common layout (compact or indented), every track with the same step keys; None for
    anything else (the caller then decodes the file)."""
    try:
        numbers = orjson.loads(b"[" + data.translate(_NUMBERS_TABLE, _NUMBERS_DROPPED)[1:] + b"]")
    except orjson.JSONDecodeError:
        return None
    layout = data.translate(_LAYOUT_TABLE, _DIGITS)
    if b'"#' in layout:
        return None
    layout = layout.translate(None, _MARK)
    steps = layout.count(b"x")
    tracks = len(numbers) - 4 * steps
    if tracks <= 0 or steps % tracks:
        return None
    per_track = steps // tracks
    track = _track_layout(per_track)
    if layout != b"{" + b",".join([track] * tracks) + b"}":
        return None
    stride = 1 + 4 * per_track
    table = np.fromiter(numbers, np.float64, len(numbers)).reshape(tracks, stride)
    keys_table = table[:, 1::4]
    if table[:, 0].max() >= _EXACT_INTEGERS or (per_track and keys_table.max() >= _EXACT_INTEGERS):
        return None
    if not (keys_table == keys_table[0]).all():
        return None
    ids = tuple(map(str, numbers[0::stride]))
    keys = tuple(map(str, numbers[1:stride:4]))
    if len(set(ids)) != tracks or len(set(keys)) != per_track:
        return None
    offsets = table[:, 1:].reshape(tracks, per_track, 4)[:, :, 1:].reshape(-1, 3)
    return ids, [keys] * tracks, offsets


@lru_cache(maxsize=4)  # a log's tracks mostly share one horizon; a few bounds the memory
def _track_layout(per_track: int) -> bytes:
    """The text of a track of ``per_track`` steps with its numbers taken out."""
    return b'"":{' + b",".join([b'"":{"x":,"y":,"z":}'] * per_track) + b"}"
