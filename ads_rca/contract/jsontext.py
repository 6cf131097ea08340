"""JSON text for the contract's String payloads and Marker ``text`` fields: strict, lossless.

Strict: no NaN/Infinity literals (any JSON parser reads every payload); non-finite numbers
travel as ``null`` with the ``"$nonfinite"`` annotation of :mod:`ads_rca.foundation.strictjson`,
which
:func:`loads_json` undoes, so subscribers get back exactly the values that were sent.
orjson is fast and keeps key order but cannot hold integers beyond 64 bits (writing them
fails, reading them gives floats); those documents go through the json module. Texts with
NaN/Infinity literals (bags recorded before the strict convention) are still read.

Texts come from the wire (anyone on the domain can publish) or from a bag nobody checked, so
:func:`loads_json` fails in one way only, :class:`~ads_rca.contract.errors.JsonTextError`
(a MalformedMessage), for invalid JSON and for nesting deeper than the parsers read (orjson
stops at 1024 levels; the json module would overflow Python's stack: RecursionError).
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping
from typing import Any

import orjson

from ads_rca.contract.errors import JsonTextError
from ads_rca.foundation.strictjson import NONFINITE_KEY, all_finite, from_strict, to_strict

#: 19 digits in a row: maybe an integer orjson cannot hold (in a string too: then harmless).
_LONG_DIGITS = re.compile(r"[0-9]{19}")


def dumps_json(document: object) -> str:
    """Compact strict JSON; unchanged text for documents with only finite numbers."""
    try:
        text = orjson.dumps(document).decode()
    except TypeError:  # int beyond 64 bits
        return json.dumps(to_strict(document), separators=(",", ":"), allow_nan=False)
    if ("null" in text and not all_finite(document)) or _has_annotation_key(document):
        return orjson.dumps(to_strict(document)).decode()
    return text


def loads_json(text: str) -> Any:
    """The document :func:`dumps_json` was given (huge integers stay integers).

    Raises :class:`JsonTextError` for anything that is not such a document."""
    try:
        if _LONG_DIGITS.search(text):  # orjson reads integers beyond 64 bits as floats
            return from_strict(json.loads(text))
        try:
            document = orjson.loads(text)
        except orjson.JSONDecodeError as error:
            if "depth limit" in str(error):
                raise JsonTextError("nested too deep: more than 1024 levels") from None
            document = json.loads(text)  # NaN/Infinity literals
    except RecursionError:
        raise JsonTextError("nested too deep for the parser") from None
    except JsonTextError:
        raise
    except ValueError as error:
        raise JsonTextError(f"invalid JSON: {error}") from None
    return from_strict(document)


def _has_annotation_key(document: object) -> bool:
    return isinstance(document, Mapping) and NONFINITE_KEY in document
