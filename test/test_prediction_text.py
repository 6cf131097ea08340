"""A predictions file read from its text (ads_rca.io.prediction_text) must give exactly what
decoding it and taking it apart gives, or nothing (then the reader decodes it and says what
is wrong): clean files in every layout a writer makes, hostile ones, and random damage."""

from __future__ import annotations

import json
import random
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import orjson
import pytest

from ads_rca.io.json_log import read_run_log
from ads_rca.io.json_writer import write_run_log
from ads_rca.io.prediction_text import prediction_parts_from_text
from ads_rca.io.records import PredictionParts, prediction_parts
from ads_rca.synth import synthesise


def decoded_parts(data: bytes) -> PredictionParts | None:
    """What the reader gets by decoding the file: the parts of a clean file, else None."""
    try:
        document = orjson.loads(data)
    except orjson.JSONDecodeError:
        return None
    return prediction_parts(document)


def assert_same_or_none(data: bytes) -> PredictionParts | None:
    fast = prediction_parts_from_text(data)
    if fast is not None:
        expected = decoded_parts(data)
        assert expected is not None, data[:200]
        assert fast[0] == expected[0] and fast[1] == expected[1]
        assert fast[2].dtype == expected[2].dtype == np.float64
        assert fast[2].shape == expected[2].shape
        assert fast[2].tobytes() == expected[2].tobytes()  # -0.0 and every last bit
    return fast


def tracks(ids: list[int], steps: int, seed: int = 0) -> dict[str, Any]:
    rng = random.Random(seed)
    values = [0.0, -0.0, 1e-07, -3.5e-05, 2, -7, 1e300, 123456.789, 0.1 + 0.2]
    return {
        str(i): {
            str(k): {"x": rng.choice(values), "y": rng.uniform(-1e3, 1e3), "z": rng.choice(values)}
            for k in range(steps)
        }
        for i in ids
    }


CLEAN = tracks([6273, 9458, 0, 12], 30)
WRITERS: dict[str, Callable[[Any], bytes]] = {
    "orjson": orjson.dumps,
    "json compact": lambda d: json.dumps(d, separators=(",", ":")).encode(),
    "json default": lambda d: json.dumps(d).encode(),
    "json indent 4": lambda d: json.dumps(d, indent=4).encode(),
    "json indent tab": lambda d: json.dumps(d, indent="\t").encode(),
    "CRLF": lambda d: json.dumps(d, indent=2).replace("\n", "\r\n").encode(),
}


@pytest.mark.parametrize("writer", list(WRITERS))
def test_a_clean_file_in_any_writers_layout_is_read_from_its_text(writer: str) -> None:
    data = WRITERS[writer](CLEAN)
    assert assert_same_or_none(data) is not None, "the fast path must take a clean file"
    one = WRITERS[writer](tracks([5], 1))
    assert assert_same_or_none(one) is not None


HOSTILE = {
    "key order": b'{"1":{"0":{"y":1,"x":2,"z":3}}}',
    "missing z": b'{"1":{"0":{"x":1,"y":2}}}',
    "extra key": b'{"1":{"0":{"x":1,"y":2,"z":3,"w":4}}}',
    "string number": b'{"1":{"0":{"x":"1.5","y":2,"z":3}}}',
    "NaN": b'{"1":{"0":{"x":NaN,"y":2,"z":3}}}',
    "Infinity": b'{"1":{"0":{"x":-Infinity,"y":2,"z":3}}}',
    "past the float range": b'{"1":{"0":{"x":1e400,"y":2,"z":3}}}',
    "null": b'{"1":{"0":{"x":null,"y":2,"z":3}}}',
    "true": b'{"1":{"0":{"x":true,"y":2,"z":3}}}',
    "a list for a number": b'{"1":{"0":{"x":[1],"y":2,"z":3}}}',
    "a list for a step": b'{"1":{"0":[1,2,3]}}',
    "a list for the file": b'[{"1":{"0":{"x":1,"y":2,"z":3}}}]',
    "duplicate track": b'{"1":{"0":{"x":1,"y":2,"z":3}},"1":{"0":{"x":4,"y":5,"z":6}}}',
    "duplicate step": b'{"1":{"0":{"x":1,"y":2,"z":3},"0":{"x":4,"y":5,"z":6}}}',
    "duplicate x": b'{"1":{"0":{"x":1,"x":2,"z":3}}}',
    "different step keys": b'{"1":{"0":{"x":1,"y":2,"z":3}},"2":{"1":{"x":4,"y":5,"z":6}}}',
    "different horizons": b'{"1":{"0":{"x":1,"y":2,"z":3}},"2":{}}',
    "tracks without steps": b'{"1":{},"2":{}}',
    "negative zero key": b'{"-0":{"0":{"x":1,"y":2,"z":3}}}',
    "negative key": b'{"-5":{"0":{"x":1,"y":2,"z":3}}}',
    "float key": b'{"1.5":{"0":{"x":1,"y":2,"z":3}}}',
    "exponent key": b'{"1e2":{"0":{"x":1,"y":2,"z":3}}}',
    "float step key": b'{"1":{"0.0":{"x":1,"y":2,"z":3}}}',
    "leading zero key": b'{"07":{"0":{"x":1,"y":2,"z":3}}}',
    "space in key": b'{" 7":{"0":{"x":1,"y":2,"z":3}}}',
    "space after key": b'{"7 ":{"0":{"x":1,"y":2,"z":3}}}',
    "space in x": b'{"7":{"0":{" x":1,"y":2,"z":3}}}',
    "space before colon": b'{"7" :{"0":{"x":1,"y":2,"z":3}}}',
    "escaped key": b'{"\\u0037":{"0":{"x":1,"y":2,"z":3}}}',
    "letter key": b'{"a7":{"0":{"x":1,"y":2,"z":3}}}',
    "key past 2**53": b'{"9007199254740993":{"0":{"x":1,"y":2,"z":3}}}',
    "key past 64 bits": b'{"18446744073709551616":{"0":{"x":1,"y":2,"z":3}}}',
    "keys equal as floats only": (
        b'{"1":{"9007199254740992":{"x":1,"y":2,"z":3}},'
        b'"2":{"9007199254740993":{"x":1,"y":2,"z":3}}}'
    ),
    "space inside a number": b'{"1":{"0":{"x":1 .5,"y":2,"z":3}}}',
    "two numbers": b'{"1":{"0":{"x":1 5,"y":2,"z":3}}}',
    "empty value": b'{"1":{"0":{"x":,"y":2,"z":3}}}',
    "plus sign": b'{"1":{"0":{"x":+1,"y":2,"z":3}}}',
    "double comma": b'{"1":{"0":{"x":1,,"y":2,"z":3}}}',
    "comma for colon": b'{"1",{"0":{"x":1,"y":2,"z":3}}}',
    "colon for comma": b'{"1":{"0":{"x":1:"y":2,"z":3}}}',
    "truncated": b'{"1":{"0":{"x":1,"y":2,"z":3}',
    "trailing text": b'{"1":{"0":{"x":1,"y":2,"z":3}}}x',
    "two documents": b'{"1":{"0":{"x":1,"y":2,"z":3}}}{}',
    "byte order mark": b'\xef\xbb\xbf{"1":{"0":{"x":1,"y":2,"z":3}}}',
    "leading space": b' {"1":{"0":{"x":1,"y":2,"z":3}}}',
    "invalid UTF-8": b'{"1\xff":{"0":{"x":1,"y":2,"z":3}}}',
    "empty": b"",
    "only braces": b"{}",
    "a number": b"5",
}


@pytest.mark.parametrize("name", list(HOSTILE))
def test_a_file_off_the_common_layout_is_left_to_the_decoder(name: str) -> None:
    """Each is either read exactly as decoding reads it or refused; every one of these is
    refused (the decoder reports it, or it is not the common layout)."""
    data = HOSTILE[name]
    assert assert_same_or_none(data) is None


def test_randomly_damaged_files_are_read_as_decoded_or_refused() -> None:
    """Bytes deleted, doubled or replaced by JSON's structural characters and digits: the
    result is always what decoding gives, or None."""
    rng = random.Random(20261128)
    sources = [WRITERS[w](tracks([3, 41], 4, seed=s)) for s, w in enumerate(WRITERS)]
    alphabet = b'{}[]":,.-+eE0123456789 \nxyz'
    taken = 0
    for _ in range(3000):
        data = bytearray(rng.choice(sources))
        for _edit in range(rng.randint(1, 3)):
            at = rng.randrange(len(data))
            action = rng.randrange(3)
            if action == 0:
                del data[at]
            elif action == 1:
                data.insert(at, data[at])
            else:
                data[at] = rng.choice(alphabet)
        taken += assert_same_or_none(bytes(data)) is not None
    assert 0 < taken < 3000  # some damage (a digit for a digit) leaves a clean file


def test_a_log_read_with_the_text_path_equals_one_read_by_decoding(tmp_path: Path) -> None:
    """Whole logs, single process and forked readers: the same predictions as decoding and
    parsing each file (the text path off by giving every file a leading space, which it
    refuses)."""
    from logcompare import assert_logs_equal

    log = write_run_log(synthesise("cut_in", "prediction", seed=3, frames=200), tmp_path / "a")
    spaced = tmp_path / "b"
    spaced.mkdir()
    for path in log.rglob("*"):
        target = spaced / path.relative_to(log)
        if path.is_dir():
            target.mkdir(exist_ok=True)
        elif path.parent.name.startswith("predictions"):
            target.write_bytes(b" " + path.read_bytes())
        else:
            target.write_bytes(path.read_bytes())
    clean = [p for p in (log / "predictions").iterdir() if p.read_bytes() != b"{}"]
    assert clean and all(prediction_parts_from_text(p.read_bytes()) for p in clean)
    for workers in (1, 2):
        fast, decoded = read_run_log(log, workers=workers), read_run_log(spaced, workers=workers)
        assert_logs_equal(fast, decoded, angle_tol=0.0)
        assert list(fast.problems) == list(decoded.problems)
