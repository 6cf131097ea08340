"""Every JSON document the project emits is strict, and lossless.

NaN and infinity travel as ``null`` named in the top-level ``"$nonfinite"`` map (JSON Pointer
→ "nan" / "inf" / "-inf"; docs/topics.md). Checked with a parser that rejects the
NaN/Infinity literals on a log full of non-finite values (NaN, Infinity and 1e400 in
metadata, poses, actors, boxes, predictions, plans): the convention itself; the offline
outputs (``diagnose --json``, ``inspect --json``, ``convert``); and over real DDS every
message a real subscriber (the recorder, ``topic_summary``) received from the player,
monitors and aggregator, with the live verdict still equal to ``diagnose``'s and the
run/metadata document read back exactly.
"""

from __future__ import annotations

import json
import math
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import orjson
import pytest
from commandline import run_cli
from logcompare import assert_logs_equal
from rosrun import run_pair
from verdicts import assert_close, failed_flags, verdict_keys

from ads_rca.contract.assembler import run_metadata
from ads_rca.contract.cdr_decode import decode_string
from ads_rca.contract.jsontext import dumps_json, loads_json
from ads_rca.contract.playback import METADATA_DOCUMENT_KEY, metadata_message, read_document
from ads_rca.contract.rosmsg import deserialize
from ads_rca.diagnosis.engine import diagnose
from ads_rca.foundation.strictjson import (
    NONFINITE_KEY,
    VALUE_KEY,
    dumps,
    from_strict,
    loads,
    to_strict,
)
from ads_rca.live.results import LiveResult
from ads_rca.model import RunLog, RunMetadata
from ads_rca.oracles.base import OracleResult
from ads_rca.params import make_params
from ads_rca.ros.launcher import ManagedProcess
from ads_rca.sources.bag.reader import iter_bag
from ads_rca.sources.log.reader import read_run_log
from ads_rca.sources.log.writer import write_run_log
from ads_rca.sources.registry import open_run
from ads_rca.synth import synthesise

if TYPE_CHECKING:
    from conftest import RosEnv

pytestmark = pytest.mark.timeout(240)

NAN, INF = math.nan, math.inf


def strict(text: str | bytes) -> Any:
    """Parse as RFC 8259 demands: a NaN/Infinity literal (or 1e400) is an error."""

    def reject(constant: str) -> None:
        raise AssertionError(f"non-strict JSON: {constant} in {str(text)[:200]}")

    document = json.loads(text, parse_constant=reject)
    orjson.loads(text)  # orjson is strict too (it also refuses 1e400)
    return document


def same(a: Any, b: Any) -> bool:
    """Equal, NaN equal to NaN, key order and types included."""
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a):
        return math.isnan(b)
    if type(a) is not type(b):
        return False
    if isinstance(a, dict):
        return list(a) == list(b) and all(same(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    return bool(a == b)


def annotated_nulls(document: Any) -> Iterator[tuple[str, str]]:
    """The ``$nonfinite`` entries of a strict document; each must point at a null."""
    for pointer, kind in (document.get(NONFINITE_KEY) or {}).items():
        node = document
        for raw in pointer[1:].split("/"):
            token = raw.replace("~1", "/").replace("~0", "~")
            node = node[int(token)] if isinstance(node, list) else node[token]
        assert node is None, pointer
        assert kind in ("nan", "inf", "-inf")
        yield pointer, kind


# --- the convention -------------------------------------------------------------------------

DOCUMENTS: list[Any] = [
    {"a": 1, "b": [1.0, NAN, {"c": -INF}], "d/e~f": INF, "": NAN},
    [NAN, 1, [INF, "x"]],
    NAN,
    -INF,
    1.5,
    "NaN",
    None,
    {"x": None, NONFINITE_KEY: {"/x": "nan"}},  # a log forging the annotation
    {NONFINITE_KEY: 3, "$$nonfinite": 4, VALUE_KEY: [NAN], "$$value": 1},
    {VALUE_KEY: [NAN]},
    {"$$value": 2, "$$nonfinite": None},
    {"x": {NONFINITE_KEY: {"/y": "inf"}, "y": None}},
    {"0": [NAN], "big": 2**70, "t": (1.0, INF)},
]


@pytest.mark.parametrize("document", DOCUMENTS, ids=range(len(DOCUMENTS)))
def test_strict_text_reads_back_exactly(document: Any) -> None:
    expected = json.loads(json.dumps(document))  # tuples as lists, NaN kept
    for text in (dumps(document), dumps(document, indent=1), dumps_json(document)):
        parsed = strict(text)
        assert same(loads(text), expected), text
        assert same(loads_json(text), expected), text
        assert same(from_strict(parsed), expected)
        if isinstance(parsed, dict):
            list(annotated_nulls(parsed))


def test_finite_documents_are_unchanged() -> None:
    document = {"id": "7", "score": 0.5, "keys": ["1", "0"], "nested": {"$x": [1, None]}}
    assert dumps_json(document) == orjson.dumps(document).decode()
    assert to_strict(document) == document


def test_the_annotation_names_each_value() -> None:
    document = to_strict({"m": {"iou": NAN, "gap": [1.0, -INF]}, "speed": INF})
    assert document == {
        "m": {"iou": None, "gap": [1.0, None]},
        "speed": None,
        NONFINITE_KEY: {"/m/iou": "nan", "/m/gap/1": "-inf", "/speed": "inf"},
    }


def test_monitor_results_and_metadata_survive_the_strict_text() -> None:
    """What the aggregator and the monitors read is what was sent, NaN camera included."""
    result = OracleResult("planning", 100, True, {"c_plan": INF, "gap": [NAN, 1.0]}, {"m": NAN})
    live = LiveResult(index=2, result=result, frame=2)
    text = dumps_json(live.to_document())
    strict(text)
    back = LiveResult.from_document(loads_json(text))
    assert same(back.result.metrics, result.metrics)
    assert same(back.result.thresholds, result.thresholds)
    raw = {"timesteps_per_frame": 50, "ego_config": {"camera": {"fov": NAN}}, "x": -INF}
    log = RunLog(RunMetadata(50, (1.3, NAN, INF), 10, 20, raw=raw), frames=(50,), source="s")
    msg = metadata_message(log)
    strict(msg.data)
    document = read_document(msg)
    assert same(document[METADATA_DOCUMENT_KEY], log.metadata.to_dict())
    metadata = run_metadata(document)
    assert same(list(metadata.camera_loc), [1.3, NAN, INF])
    assert same(dict(metadata.raw), log.metadata.to_dict())


# --- a log full of non-finite values -----------------------------------------------------------


def write_nonfinite_log(folder: Path) -> Path:
    """A cut-in crash with NaN, Infinity and 1e400 in every folder and in metadata.json."""
    write_run_log(synthesise("cut_in", "perception", seed=4), folder)
    metadata = json.loads((folder / "metadata.json").read_text())
    metadata["ego_config"]["camera"]["fov"] = NAN
    metadata["weather"] = {"fog": INF, "rain": -INF, "wind": [1.0, NAN]}
    metadata[NONFINITE_KEY] = {"/weather": "nan"}  # the log forging our annotation
    (folder / "metadata.json").write_text(json.dumps(metadata))
    poses = sorted((folder / "pose").iterdir())
    for path in poses[3:5]:
        pose = json.loads(path.read_text())
        pose["speed"] = "1e400"
        path.write_text(json.dumps(pose))
    for n, path in enumerate(sorted((folder / "bboxes").iterdir())):
        boxes = json.loads(path.read_text())
        for box in boxes:
            box["score"] = [NAN, INF, "__1e400__"][n % 3]
            box["attrs"] = {"depth": -INF}
        path.write_text(json.dumps(boxes).replace('"__1e400__"', "1e400"))
    for path in sorted((folder / "actors").iterdir())[:10]:
        actors = json.loads(path.read_text())
        actors[list(actors)[-1]]["extent"]["z"] = NAN
        path.write_text(json.dumps(actors))
    for path in sorted((folder / "predictions").iterdir())[:10]:
        tracks = json.loads(path.read_text())
        for steps in tracks.values():
            steps[next(iter(steps))]["z"] = INF
        path.write_text(json.dumps(tracks))
    for path in sorted((folder / "waypoint").iterdir())[:10]:
        plan = json.loads(path.read_text())
        plan[next(iter(plan))]["speed"] = NAN
        path.write_text(json.dumps(plan))
    return folder


@pytest.fixture(scope="module")
def nonfinite_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_nonfinite_log(tmp_path_factory.mktemp("strict") / "log")


def bag_json_texts(bag: Path) -> Iterator[tuple[str, str]]:
    """(topic, text) of every JSON a bag holds: String payloads, Marker texts, and the
    JSON-valued diagnostic key/values."""
    for message in iter_bag(bag):
        kind = message.msg_type.replace("/msg/", "/")
        if kind == "std_msgs/String":
            yield message.topic, decode_string(message.data)
        elif kind == "visualization_msgs/MarkerArray":
            for marker in deserialize(message.data, message.msg_type).markers:
                if marker.text.startswith("{"):
                    yield message.topic, marker.text
        elif kind == "diagnostic_msgs/DiagnosticArray":
            for status in deserialize(message.data, message.msg_type).status:
                for pair in status.values:
                    if pair.value[:1] in ("[", "{"):
                        yield message.topic, pair.value


def test_the_log_really_is_full_of_non_finite_values(nonfinite_log: Path) -> None:
    log = read_run_log(nonfinite_log)
    assert sum("1e400" in p.issue for p in log.problems) == 2
    assert math.isnan(log.metadata.raw["ego_config"]["camera"]["fov"])
    scores = [e.get("score") for boxes in log.bboxes.values() for e in boxes.extras]
    assert any(isinstance(s, float) and math.isnan(s) for s in scores) and INF in scores


@pytest.mark.parametrize("semantics", ["corrected", "reference"])
def test_diagnose_json_is_strict_and_names_what_is_null(
    nonfinite_log: Path, tmp_path: Path, semantics: str
) -> None:
    out = tmp_path / "verdict.json"
    run_cli(
        "diagnose", str(nonfinite_log), "--semantics", semantics, "--json", str(out), check=True
    )
    document = strict(out.read_text())
    named = dict(annotated_nulls(document))
    assert named and all(p.startswith(("/frames/", "/evidence/")) for p in named)
    offline = diagnose(read_run_log(nonfinite_log), make_params(semantics)).to_json()
    assert named == offline[NONFINITE_KEY]


def test_inspect_json_is_strict(nonfinite_log: Path) -> None:
    document = strict(run_cli("inspect", str(nonfinite_log), "--json", check=True).stdout)
    assert document["analysed_frames"] == len(read_run_log(nonfinite_log).frames)


def test_convert_writes_strict_json_and_reads_it_back_exactly(
    nonfinite_log: Path, tmp_path: Path
) -> None:
    bag, back = tmp_path / "bag", tmp_path / "back"
    run_cli("convert", str(nonfinite_log), str(bag), check=True)
    topics_seen = set()
    annotated = set()
    for topic, text in bag_json_texts(bag):
        document = strict(text)
        topics_seen.add(topic)
        if isinstance(document, dict) and NONFINITE_KEY in document:
            annotated.add(topic)
    assert {"/ads_rca/run/metadata", "/ads_rca/perception/detections"} <= annotated
    assert {"/ads_rca/player/status", "/ads_rca/run/frame"} <= topics_seen
    original = read_run_log(nonfinite_log)
    assert_logs_equal(original, open_run(bag))
    run_cli("convert", str(bag), str(back), check=True)
    assert_logs_equal(original, read_run_log(back))


# --- over real DDS ------------------------------------------------------------------------------


def test_live_graph_emits_strict_json_and_the_same_verdict(
    ros_env: RosEnv, tmp_path: Path, nonfinite_log: Path
) -> None:
    """replay with the recorder: every JSON the player, monitors and aggregator sent, as a
    real subscriber received it, is strict; the verdict equals diagnose; the recorded bag
    diagnoses as the original log does."""
    out, bag = tmp_path / "verdict.json", tmp_path / "bag"
    argv = [sys.executable, "-m", "ads_rca.cli", "replay", str(nonfinite_log), "--record"]
    argv += [str(bag), "--json", str(out), "--domain-id", str(ros_env.domain_id)]
    replay = ManagedProcess("replay", [*argv, "--timeout", "120"], ros_env.env)
    assert replay.wait(200) == 0, replay.output
    live = strict(out.read_text())
    original = read_run_log(nonfinite_log)
    offline = diagnose(original, make_params("corrected")).to_json()
    assert live["live"]["complete"], live["live"]
    assert failed_flags(live) == failed_flags(offline)
    assert_close(verdict_keys(live), verdict_keys(offline))
    assert_close(live["frames"], offline["frames"])
    assert live[NONFINITE_KEY] == offline[NONFINITE_KEY]
    annotated: set[str] = set()
    metadata_documents = []
    for topic, text in bag_json_texts(bag):
        document = strict(text)
        if isinstance(document, dict) and NONFINITE_KEY in document:
            annotated.add(topic)
        if topic.endswith("/run/metadata"):
            metadata_documents.append(loads_json(text))
    assert any("/metrics/" in topic for topic in annotated), annotated
    assert "/ads_rca/run/metadata" in annotated or any("run/metadata" in t for t in annotated)
    (metadata,) = metadata_documents
    assert same(metadata[METADATA_DOCUMENT_KEY], original.metadata.to_dict())
    recorded = diagnose(open_run(bag), make_params("corrected")).to_json()
    assert_close(recorded["frames"], offline["frames"])
    assert recorded[NONFINITE_KEY] == offline[NONFINITE_KEY]


def test_topic_summary_rebuilds_the_log_and_writes_strict_json(
    ros_env: RosEnv, tmp_path: Path, nonfinite_log: Path
) -> None:
    """The assembler across DDS: the rebuilt log equals the original, metadata included."""
    rebuilt, ns = tmp_path / "rebuilt", ros_env.namespace
    result = run_pair(
        ros_env.env,
        tmp_path,
        {"log_path": str(nonfinite_log), "rate": 0.0, "topic_namespace": ns},
        {"topic_namespace": ns, "output_json": True, "output_dir": str(rebuilt)},
    )
    assert result.player_code == 0, result.player_output
    assert result.summary_code == 0, result.summary_output
    strict((tmp_path / "summary.json").read_text())
    original = read_run_log(nonfinite_log)
    assert_logs_equal(original, read_run_log(rebuilt))
