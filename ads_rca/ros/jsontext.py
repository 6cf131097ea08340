"""JSON text for the contract's String payloads and Marker ``text`` fields: strict, lossless.

Strict: no NaN/Infinity literals (any JSON parser reads every payload); non-finite numbers
travel as ``null`` with the ``"$nonfinite"`` annotation of :mod:`ads_rca.strictjson`, which
:func:`loads_json` undoes, so subscribers get back exactly the values that were sent.
orjson is fast and keeps key order but rejects integers beyond 64 bits; those documents
fall back to the json module. Texts with NaN/Infinity literals (bags recorded before the
strict convention) are still read.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any

import orjson

from ads_rca.strictjson import NONFINITE_KEY, from_strict, to_strict


def dumps_json(document: Any) -> str:
    """Compact strict JSON; unchanged text for documents with only finite numbers."""
    try:
        text = orjson.dumps(document).decode()
    except TypeError:  # int beyond 64 bits
        return json.dumps(to_strict(document), separators=(",", ":"), allow_nan=False)
    if ("null" in text and not _all_finite(document)) or _has_annotation_key(document):
        return orjson.dumps(to_strict(document)).decode()
    return text


def loads_json(text: str) -> Any:
    try:
        document = orjson.loads(text)
    except orjson.JSONDecodeError:
        document = json.loads(text)
    return from_strict(document)


def _has_annotation_key(document: Any) -> bool:
    return isinstance(document, Mapping) and NONFINITE_KEY in document


def _all_finite(document: Any) -> bool:
    if isinstance(document, float):
        return math.isfinite(document)
    if isinstance(document, Mapping):
        return all(_all_finite(v) for v in document.values())
    if isinstance(document, list | tuple):
        return all(_all_finite(v) for v in document)
    return True
