"""One typed error hierarchy under ``AdsRcaError``.

- Every exception class the package defines derives from ``AdsRcaError`` (the package
  walked with pkgutil, every module imported, the classes found with inspect); one
  ``ConfigError``; every public kind is named in docs/architecture.md's "Errors" section.
- The codec and the contract's document readers fail in one typed way,
  ``MalformedMessage`` (``CdrError`` for bytes), with the exact texts they had as bare
  ValueErrors; a caller's mistake (an unknown topic, a message object of the wrong kind)
  is not taken for a malformed message.
- The nodes that read messages catch only typed errors: no handler in them names
  ``KeyError``, ``TypeError``, ``ValueError``... (an AST walk), and no
  ``except (KeyError, TypeError, ValueError)`` is left anywhere in the package.
- The command line turns any ``AdsRcaError`` into one line and exit status 2.
"""

from __future__ import annotations

import ast
import importlib
import inspect
import pkgutil
import re
from pathlib import Path

import pytest

import ads_rca
from ads_rca.cli import main
from ads_rca.contract import cdr, cdr_decode, topics
from ads_rca.contract.assembler import RunLogAssembler, run_metadata
from ads_rca.contract.errors import (
    CdrError,
    ContractError,
    IncompleteRun,
    JsonTextError,
    MalformedMessage,
    NoStamp,
    UnknownTopic,
)
from ads_rca.errors import AdsRcaError, ConfigError, InputError
from ads_rca.live.results import FrameMarker, LiveResult
from ads_rca.sources.bag.mcap_writer import McapBagWriter
from ads_rca.sources.errors import InvalidJson, OutputExists
from ads_rca.sources.log.reader import decode_json, read_run_log

PACKAGE = Path(ads_rca.__file__).resolve().parent
ROOT = PACKAGE.parent
EXAMPLE = ROOT / "examples" / "cut_in_perception"
#: The nodes that read the contract's messages: they may catch typed errors only.
MESSAGE_READERS = ("ros/aggregator.py", "ros/monitor.py", "ros/topic_summary.py")
BUILTIN_CATCHES = {
    "Exception",
    "LookupError",
    "KeyError",
    "IndexError",
    "TypeError",
    "ValueError",
    "AttributeError",
    "ArithmeticError",
    "OverflowError",
}


def defined_exceptions() -> list[type[BaseException]]:
    """Every exception class defined (not imported) in a module of the package."""
    found: list[type[BaseException]] = []
    for module_info in pkgutil.walk_packages([str(PACKAGE)], prefix="ads_rca."):
        module = importlib.import_module(module_info.name)
        for _name, value in inspect.getmembers(module, inspect.isclass):
            if issubclass(value, BaseException) and value.__module__ == module.__name__:
                found.append(value)
    return found


def test_every_exception_class_derives_from_ads_rca_error() -> None:
    found = defined_exceptions()
    assert len(found) >= 15  # the walk did reach the subpackages
    outside = [f"{c.__module__}.{c.__qualname__}" for c in found if not issubclass(c, AdsRcaError)]
    assert outside == []
    assert [c for c in found if c.__name__ == "ConfigError"] == [ConfigError]
    assert issubclass(ConfigError, InputError)


def test_every_public_error_is_named_in_the_architecture_doc() -> None:
    text = (ROOT / "docs" / "architecture.md").read_text()
    section = text.split("\n## Errors\n", 1)[1].split("\n## ", 1)[0]
    public = {c.__name__ for c in defined_exceptions() if not c.__name__.startswith("_")}
    assert sorted(name for name in public if not re.search(rf"\b{name}\b", section)) == []


def test_malformed_cdr_raises_the_codecs_typed_error_with_its_former_text() -> None:
    log = read_run_log(EXAMPLE)
    payloads = topics.frame_payloads(log, log.frames[3])
    big_endian = b"\x00\x00\x00\x00" + payloads[topics.ODOMETRY][4:]
    with pytest.raises(CdrError) as caught:
        cdr_decode.decode_odometry(big_endian)
    assert str(caught.value) == (
        "malformed odometry: not a little-endian CDR message (encapsulation 00 01)"
    )
    assert isinstance(caught.value, MalformedMessage)
    assert isinstance(caught.value, ValueError)  # as before it was typed
    for key in (k for k in topics.DATA_TOPICS if k in payloads):  # the log's own folders
        with pytest.raises(CdrError):
            topics.decode_record(key, payloads[key][: len(payloads[key]) // 2], 50)
    with pytest.raises(CdrError, match=r"^a string claims 2147483647 bytes, 0 remain$"):
        cdr_decode.decode_string(b"\x00\x01\x00\x00\xff\xff\xff\x7f")
    with pytest.raises(NoStamp):  # well-formed: not malformed, only without a stamp
        topics.stamp_ms(topics.ACTORS, cdr.ENCAPSULATION + bytes(4))
    assert not issubclass(NoStamp, MalformedMessage)


def test_a_callers_mistake_is_not_taken_for_a_malformed_message() -> None:
    with pytest.raises(UnknownTopic) as caught:
        topics.decode_record("no/such/topic", b"", 50)
    assert not isinstance(caught.value, MalformedMessage)
    assembler = RunLogAssembler()
    with pytest.raises(AttributeError):  # a bug of the caller: not a String at all
        assembler.add(topics.FRAME, 42)
    with pytest.raises(IncompleteRun, match=r"^no run/metadata message received$"):
        assembler.build()


def test_document_readers_raise_malformed_message_with_the_readers_error_as_cause() -> None:
    with pytest.raises(MalformedMessage) as result:
        LiveResult.from_document([1, 2])  # type: ignore[arg-type]
    assert repr(result.value.__cause__) == (
        "TypeError('list indices must be integers or slices, not str')"
    )
    with pytest.raises(MalformedMessage, match=r"^unknown module 'steering'$"):
        LiveResult.from_document({"module": "steering"})
    with pytest.raises(MalformedMessage) as marker:
        FrameMarker.from_document({"stamp_ms": []})
    assert isinstance(marker.value.__cause__, TypeError)
    assert str(marker.value) == str(marker.value.__cause__)
    # Infinity where an integer belongs (an OverflowError escaped before): not an integer.
    with pytest.raises(MalformedMessage, match=r"^unusable run/metadata: TypeError\("):
        run_metadata({"timesteps_per_frame": float("inf")})
    assembler = RunLogAssembler()
    with pytest.raises(MalformedMessage, match=r"^'int' object is not iterable$"):
        assembler.add_raw(topics.FRAME, cdr.encode_string('{"published": 3, "stamp_ms": 0}'))
    with pytest.raises(JsonTextError):
        assembler.add_raw(topics.STATUS, cdr.encode_string("not json"))


def test_io_errors_are_typed() -> None:
    with pytest.raises(InvalidJson, match=r"^nested too deep: more than 1024 levels$"):
        decode_json(b"[" * 2000 + b"]" * 2000)
    with pytest.raises(InvalidJson, match=r"^Expecting value: line 1 column 1 \(char 0\)$"):
        decode_json(b"nope")


def test_the_bag_writer_refuses_a_used_folder_and_an_unknown_compression(tmp_path: Path) -> None:
    (tmp_path / "used").mkdir()
    (tmp_path / "used" / "file").write_text("x")
    with pytest.raises(OutputExists) as caught:
        McapBagWriter(tmp_path / "used")
    assert isinstance(caught.value, InputError)
    assert isinstance(caught.value, FileExistsError)  # as before it was typed
    with pytest.raises(ConfigError) as config:
        McapBagWriter(tmp_path / "new", compression="bzip")
    assert str(config.value) == "compression must be one of ['lz4', 'none', 'zstd']"


def test_message_reading_nodes_catch_only_typed_errors() -> None:
    for relative in MESSAGE_READERS:
        tree = ast.parse((PACKAGE / relative).read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.ExceptHandler) and node.type is not None:
                names = {n.id for n in ast.walk(node.type) if isinstance(n, ast.Name)}
                assert not names & BUILTIN_CATCHES, (relative, node.lineno, sorted(names))
    broad = re.compile(r"except \(KeyError, TypeError, ValueError\)")
    for path in PACKAGE.rglob("*.py"):
        assert not broad.search(path.read_text()), path


def test_the_cli_turns_an_ads_rca_error_into_one_line_and_status_2(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert issubclass(ContractError, AdsRcaError)
    assert main(["diagnose", str(EXAMPLE), "-p", "effect_time_window=soon"]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err == (
        "ads-rca diagnose: error: parameter effect_time_window: 'soon' is not a number\n"
    )
