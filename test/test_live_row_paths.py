"""A live trajectory-prediction model scored frame by frame: the planning
monitor's rule for a snapshot row's later paths (``ads_rca/live/row_paths.py``) and the
monitor core using it, without ROS. A model's path that comes after its row was judged
re-publishes the row's planning result with revision + 1, equal to what ``diagnose`` gives
the same path as a submission and to what the aggregator's verdict scores; bounds and
hostile messages are refused with one typed error.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from writers.atmacup_tables import ROWS, write_submission, write_table

from ads_rca.contract.ego_paths import (
    EgoPathRow,
    ego_path_document,
    read_ego_path,
)
from ads_rca.contract.errors import MalformedMessage
from ads_rca.contract.jsontext import dumps_json, loads_json
from ads_rca.diagnosis.engine import diagnose
from ads_rca.diagnosis.verdict import OracleResult
from ads_rca.live.aggregate import AggregatorCore
from ads_rca.live.results import FrameMarker, LiveResult
from ads_rca.live.row_paths import NO_PATHS, RowPaths, same_row
from ads_rca.live.window import MonitorCore, WindowSettings
from ads_rca.model import ALL_FOLDERS, RunLog, RunMetadata
from ads_rca.oracles.base import MODULES
from ads_rca.params import make_params
from ads_rca.sources.atmacup.reader import read_atmacup_table
from ads_rca.sources.atmacup.trajectory_scores import TRAJECTORY_SCORES_KEY
from ads_rca.sources.formats import SourceOptions

IDS = [row.ident for row in ROWS]
SHIFT = np.array([1.0, 0.0, 0.0])  # the model: the realised path 1 m further in x


@pytest.fixture
def table(tmp_path: Path) -> Path:
    write_table(tmp_path / "data")
    return tmp_path / "data"


def row(stamp: int, predicted: float | None = None, ident: str = "") -> EgoPathRow:
    """A row whose predicted path is every coordinate ``predicted`` (None: no path)."""
    path = None if predicted is None else np.full((6, 3), predicted)
    return EgoPathRow(stamp, ident, -1, None, path, "")


def result(stamp: int, revision: int = 0) -> LiveResult:
    return LiveResult(0, OracleResult("planning", stamp, False), 0, revision=revision)


def model_document(document: dict[str, Any], shift: np.ndarray = SHIFT) -> dict[str, Any]:
    """What the test model sends for the player's row: the realised path shifted."""
    predicted = (np.asarray(document["realised"]) + shift).tolist()
    return {
        "stamp_ms": document["stamp_ms"],
        "id": document["id"],
        "predicted": predicted,
        "submission": "shift-model",
    }


# --- the rule --------------------------------------------------------------------------


def test_a_row_not_yet_judged_is_merged_and_nothing_is_due() -> None:
    paths = RowPaths()
    assert not paths.add(row(0, 1.0), None) and not paths.add(row(0, 2.0), 0)
    assert paths.has(0) and not paths.has(100)
    held = paths.rows([0, 100])
    assert list(held) == [0] and held[0].predicted is not None
    assert held[0].predicted[0, 0] == 2.0  # the later path replaced the earlier
    assert paths.due() == []


def test_a_judged_rows_later_path_makes_it_due_once() -> None:
    paths = RowPaths()
    paths.add(row(0, 1.0), None)
    paths.judged_row(result(0))
    assert not paths.add(row(0, 1.0), 0)  # the same path again: nothing to say
    assert paths.due() == []
    assert paths.add(row(0, 2.0), 0) and paths.add(row(0, 3.0), 0)  # two before a poll
    (due,) = paths.due()
    assert due.paths is not None and due.paths.predicted is not None
    assert due.paths.predicted[0, 0] == 3.0 and due.result.revision == 0
    assert paths.due() == []  # taken
    paths.rescored(result(0, revision=1))
    assert paths.judged[0].rescores == 1 and paths.judged[0].result.revision == 1


def test_a_row_judged_without_paths_is_due_when_a_path_comes() -> None:
    paths = RowPaths()
    paths.judged_row(result(0))  # judged with none (timed out)
    assert not paths.has(0)
    assert paths.add(row(0, 1.0), 100)  # the window moved on: remembered all the same
    assert [d.result.stamp_ms for d in paths.due()] == [0]


def test_a_flood_for_one_row_stops_after_max_rescores() -> None:
    paths = RowPaths(max_rescores=3)
    paths.judged_row(result(0))
    for n in range(3):
        assert paths.add(row(0, float(n)), 0)
        assert len(paths.due()) == 1
        paths.rescored(result(0, revision=n + 1))
    with pytest.raises(MalformedMessage, match="scored again 3 times already"):
        paths.add(row(0, 99.0), 0)
    assert paths.judged[0].rescores == 3 and len(paths) == 1  # memory did not grow
    assert not paths.add(row(0, 2.0), 0)  # the latest path again changes nothing: taken


def test_unknown_old_stamps_and_too_many_held_rows_are_refused() -> None:
    paths = RowPaths(max_held=2)
    with pytest.raises(MalformedMessage, match="no row at 50 ms is held"):
        paths.add(row(50, 1.0), 100)  # older than the window, never judged
    paths.add(row(100, 1.0), 100)
    paths.add(row(200, 1.0), 100)
    with pytest.raises(MalformedMessage, match="2 rows are held already"):
        paths.add(row(300, 1.0), 100)
    paths.add(row(200, 2.0), 100)  # a row already held is still merged
    paths.forget_before(150)  # the window moved past 100 without judging it
    assert list(paths.held) == [200]


def test_judged_rows_beyond_the_memory_are_forgotten_oldest_first() -> None:
    paths = RowPaths(remembered=2)
    for stamp in (0, 100, 200):
        paths.add(row(stamp, 1.0), None)
        paths.judged_row(result(stamp))
    assert list(paths.judged) == [100, 200]
    with pytest.raises(MalformedMessage, match="judged more than 2 rows ago"):
        paths.add(row(0, 5.0), 100)


def test_a_rejudged_row_keeps_its_latest_paths_and_is_no_longer_due() -> None:
    paths = RowPaths()
    paths.judged_row(result(0))
    paths.add(row(0, 1.0), 0)
    paths.judged_row(result(0, revision=1))  # judged again (a collision) on the latest
    assert paths.due() == []
    judged = paths.judged[0]
    assert judged.paths is not None and judged.result.revision == 1


def test_same_row_compares_ids_and_both_paths() -> None:
    assert same_row(None, None) and not same_row(row(0, 1.0), None)
    assert same_row(row(0, math.nan), row(0, math.nan))  # NaN where both have none
    assert not same_row(row(0, 1.0, "a_1"), row(0, 1.0, "b_1"))
    assert not same_row(row(0, 1.0), row(0))


@pytest.mark.parametrize(
    ("document", "expected"),
    [
        ({"stamp_ms": 0, "predicted": [[1e300, 0, 0]] * 6}, "beyond 1e\\+06 m"),
        ({"stamp_ms": 0, "realised": [[0, -2e6, 0]] * 6}, "beyond 1e\\+06 m"),
        ({"stamp_ms": 0, "predicted": [[math.nan, 0, 0]] * 6}, "beyond"),
        ({"stamp_ms": 0, "predicted": [[math.inf, 0, 0]] * 6}, "beyond"),
        ({"stamp_ms": 0, "row": -2}, "row is not an integer from -1 up"),
        ({"stamp_ms": 2**60}, "stamp_ms is not a timestamp"),
    ],
)
def test_absurd_numbers_in_a_path_message_are_refused(
    document: dict[str, Any], expected: str
) -> None:
    with pytest.raises(MalformedMessage, match=expected):
        read_ego_path(document)


# --- the monitor core ------------------------------------------------------------------


def live_metadata(log: RunLog) -> RunMetadata:
    """The metadata as run/metadata carries it (the recording's inputs in its document)."""
    return replace(log.metadata, raw=log.metadata_document())


def play(log: RunLog, core: MonitorCore, aggregator: AggregatorCore | None = None) -> None:
    """The player's messages for every row (records, its paths, the marker), then its end."""
    clock = 0.0
    core.set_metadata(live_metadata(log), clock)
    if aggregator is not None:
        aggregator.set_metadata(live_metadata(log), log.source, clock)
    for index, stamp in enumerate(log.frames):
        clock += 0.1
        folders = set()
        for folder in ALL_FOLDERS:
            record = log.folder(folder).get(stamp)
            if record is not None:
                folders.add(folder)
                core.add_record(folder, stamp, record, clock)
        document = ego_path_document(log, stamp)
        assert document is not None
        wire = read_ego_path(loads_json(dumps_json(document)))
        core.add_ego_path(wire, clock)
        marker = FrameMarker(index, stamp, frozenset(folders), snapshot=True)
        core.add_marker(marker, clock)
        if aggregator is not None:
            aggregator.add_ego_path(wire)
            aggregator.add_marker(marker, clock)
    core.set_finished(clock + 0.1, len(log.frames))
    if aggregator is not None:
        aggregator.set_finished(clock + 0.1, len(log.frames))


def shifted_submission(table: Path) -> Path:
    paths = [tuple((x + 1.0, y, z) for x, y, z in r.path) for r in ROWS]
    return write_submission(table / "shift.csv", paths)


def test_a_models_later_path_rescores_each_row_as_diagnose_and_the_verdict_do(
    table: Path,
) -> None:
    """The player's rows without a prediction are judged (nothing scored); the model's
    paths come after: each row's planning result comes again, revision 1, with ADE 1.0."""
    log = read_atmacup_table(table)
    core = MonitorCore(MODULES, make_params("corrected"))  # the monitors process: shared
    aggregator = AggregatorCore(make_params("corrected"))
    play(log, core, aggregator)
    first = core.poll(1.0)
    assert sorted({r.module for r in first}) == sorted(MODULES) and len(first) == 4 * 3
    planning = [r for r in first if r.module == "planning"]
    assert all("row_id" not in r.result.metrics and r.revision == 0 for r in planning)
    assert core.rescores_rows and len(core.row_paths.judged) == 3
    for stamp in log.frames:
        document = ego_path_document(log, stamp)
        assert document is not None
        answer = read_ego_path(loads_json(dumps_json(model_document(document))))
        core.add_ego_path(answer, 1.1)
        aggregator.add_ego_path(answer)
    again = core.poll(1.2)
    assert [r.module for r in again] == ["planning"] * 3  # the other modules are not re-sent
    assert [r.stamp_ms for r in again] == list(log.frames)
    assert all(r.revision == 1 and not r.incomplete for r in again)
    # Hand arithmetic: every horizon 1 m off in x alone: distance 1, ADE = FDE = 1.0;
    # MAE = six x errors of 1 over 18 values = 1/3.
    for live, ident in zip(again, IDS, strict=True):
        metrics = live.result.metrics
        assert metrics["row_id"] == ident
        assert metrics["trajectory_ade"] == pytest.approx(1.0)
        assert metrics["trajectory_fde"] == pytest.approx(1.0)
        assert metrics["trajectory_mae"] == pytest.approx(1 / 3)
    assert core.poll(1.3) == []  # nothing new
    # diagnose, given the same paths as a submission, scores each frame alike
    sub = shifted_submission(table)
    offline = diagnose(
        read_atmacup_table(table, source=SourceOptions(submission=str(sub))),
        make_params("corrected"),
    )
    for live, frame in zip(again, offline.frames, strict=True):
        want = frame.results["planning"]
        assert live.result.metrics == want.metrics and live.result.skipped == want.skipped
    # the aggregator keeps each frame's highest revision and scores the merged rows of the
    # analysed frames (a path for a stamp never played counts for nothing)
    aggregator.add_ego_path(row(50, 1.0))
    for live in [*first, *again]:
        aggregator.add_result(live, 1.3)
    outcome = aggregator.poll(1.4)
    assert outcome is not None
    document = outcome.document
    offline_document = offline.to_json()
    for frame, want in zip(document["frames"], offline_document["frames"], strict=True):
        assert frame["planning"] == want["planning"]
    live_scores = dict(document[TRAJECTORY_SCORES_KEY])
    offline_scores = dict(offline_document[TRAJECTORY_SCORES_KEY])
    assert live_scores.pop("submission") == "shift-model"
    offline_scores.pop("submission")
    assert live_scores == offline_scores
    assert live_scores["per_row"]["ade"] == pytest.approx([1.0, 1.0, 1.0])
    per_frame = [r.result.metrics["trajectory_ade"] for r in again]
    assert per_frame == live_scores["per_row"]["ade"]  # the same numbers, not just close


def test_a_models_path_before_the_row_is_judged_is_scored_the_first_time(table: Path) -> None:
    log = read_atmacup_table(table)
    core = MonitorCore("planning", make_params("corrected"))
    play(log, core)
    for stamp in log.frames:  # the model answers before the monitor judges (look-ahead)
        document = ego_path_document(log, stamp)
        assert document is not None
        core.add_ego_path(read_ego_path(model_document(document)), 0.5)
    results = core.poll(1.0)
    assert [r.revision for r in results] == [0, 0, 0]
    assert [r.result.metrics["trajectory_ade"] for r in results] == pytest.approx([1.0] * 3)
    assert core.poll(1.1) == []


def test_a_row_judged_without_its_paths_is_complete_once_they_come(table: Path) -> None:
    log = read_atmacup_table(table)
    core = MonitorCore("planning", make_params("corrected"))
    core.set_metadata(live_metadata(log), 0.0)
    core.add_marker(FrameMarker(0, 0, frozenset(), snapshot=True), 0.1)
    core.set_finished(0.1, 1)
    (late,) = core.poll(0.2 + core.settings.input_timeout_s)  # the row never came
    assert NO_PATHS in late.incomplete and "row_id" not in late.result.metrics
    document = ego_path_document(log, 0)
    assert document is not None
    core.add_ego_path(read_ego_path(model_document(document)), 10.0)  # a model: no realised
    (still,) = core.poll(10.1)
    assert still.revision == 1 and NO_PATHS in still.incomplete  # nothing to score it against
    assert "row_id" not in still.result.metrics
    core.add_ego_path(read_ego_path(document), 10.2)  # the player's, very late
    (scored,) = core.poll(10.3)
    assert scored.revision == 2 and NO_PATHS not in scored.incomplete
    assert scored.result.metrics["trajectory_ade"] == pytest.approx(1.0)


def test_a_collision_after_a_rescore_judges_the_row_again_higher_still(table: Path) -> None:
    log = read_atmacup_table(table)
    core = MonitorCore("planning", make_params("corrected"))
    play(log, core)
    core.poll(1.0)
    document = ego_path_document(log, 0)
    assert document is not None
    core.add_ego_path(read_ego_path(model_document(document)), 1.1)
    (rescored,) = core.poll(1.2)
    assert rescored.revision == 1
    core.set_collision(2, 1.3)  # a live collision topic: held frames judged again
    again = core.poll(1.4)
    first = next(r for r in again if r.stamp_ms == 0)
    assert first.revision == 2  # above the rescore: the aggregator keeps it
    assert first.result.metrics == rescored.result.metrics  # judged on the latest paths


def test_a_message_for_a_stamp_the_window_passed_is_refused_by_the_core(table: Path) -> None:
    """A stamp between rows is held while the window may still reach it (bounded, then
    forgotten); once the window passed it, a message for it is refused."""
    log = read_atmacup_table(table)
    settings = WindowSettings(history_frames=1)  # the window keeps only the last row judged
    core = MonitorCore("planning", make_params("corrected"), settings)
    play(log, core)
    core.poll(1.0)
    assert core.row_paths.held == {}  # the judged rows moved to the remembered ones
    with pytest.raises(MalformedMessage, match="no row at 50 ms is held"):
        core.add_ego_path(row(50, 1.0), 1.1)  # between rows 0 and 100 ms: no frame there
    assert core.poll(1.2) == []
    core.add_ego_path(row(0, 1.0), 1.3)  # row 0 is remembered though the window passed it
    assert [r.revision for r in core.poll(1.4)] == [1]
    reference = MonitorCore("planning", make_params("reference"))
    reference.set_metadata(live_metadata(log), 0.0)
    reference.add_ego_path(row(50, 1.0), 0.1)  # reference scores no rows: taken, unused
    assert not reference.wants_paths and len(reference.row_paths) == 0


def test_a_flood_for_one_judged_row_is_bounded_in_results(table: Path) -> None:
    log = read_atmacup_table(table)
    core = MonitorCore("planning", make_params("corrected"))
    play(log, core)
    core.poll(1.0)
    refused = 0
    published = 0
    for n in range(40):
        try:
            core.add_ego_path(row(0, float(n)), 1.1)
        except MalformedMessage:
            refused += 1
        published += len(core.poll(1.1))
    limit = core.row_paths.max_rescores
    assert published == limit and refused == 40 - limit and len(core.row_paths) == 3


def test_the_aggregator_holds_a_bounded_number_of_rows(
    table: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from ads_rca.live import aggregate

    monkeypatch.setattr(aggregate, "MAX_ROWS", 2)
    core = AggregatorCore(make_params("corrected"))
    core.add_ego_path(row(0, 1.0))
    core.add_ego_path(row(100, 1.0))
    with pytest.raises(MalformedMessage, match="2 rows are held already"):
        core.add_ego_path(row(200, 1.0))
    core.add_ego_path(row(100, 2.0))  # a row held is still merged
    assert sorted(core.ego_paths) == [0, 100]


def _judged_beside_a_model(table: Path, answered: int) -> tuple[RunLog, AggregatorCore]:
    """The aggregator after every module judged every row, the model having answered the
    first ``answered`` rows (its answers, as a model's, carry no realised path)."""
    log = read_atmacup_table(table)
    core = MonitorCore(MODULES, make_params("corrected"))
    aggregator = AggregatorCore(make_params("corrected"), verdict_timeout_s=5.0)
    play(log, core, aggregator)
    for stamp in log.frames[:answered]:
        document = ego_path_document(log, stamp)
        assert document is not None
        aggregator.add_ego_path(read_ego_path(loads_json(dumps_json(model_document(document)))))
    for live in core.poll(1.0):
        aggregator.add_result(live, 1.0)
    return log, aggregator


@pytest.mark.parametrize("answered", [0, 2])
def test_the_verdict_waits_for_a_models_last_answers_only_when_a_model_answers(
    table: Path, answered: int
) -> None:
    """No predicted path heard: no model, the verdict is due at once, nothing scored. A
    model that answered rows 0 and 100: the verdict waits for row 200's answer (the
    monitors' results came first, as they may over DDS) and then scores all three."""
    log, aggregator = _judged_beside_a_model(table, answered)
    if answered == 0:
        outcome = aggregator.poll(1.1)
        assert outcome is not None and outcome.complete
        assert outcome.document[TRAJECTORY_SCORES_KEY]["scored"] == 0
        return
    assert aggregator.poll(1.1) is None and aggregator.poll(5.9) is None
    last = ego_path_document(log, log.frames[-1])
    assert last is not None
    aggregator.add_ego_path(read_ego_path(model_document(last)))
    outcome = aggregator.poll(6.0)
    assert outcome is not None and outcome.complete
    scores = outcome.document[TRAJECTORY_SCORES_KEY]
    assert scores["submission"] == "shift-model" and scores["scored"] == 3
    assert scores["per_row"]["ade"] == pytest.approx([1.0, 1.0, 1.0])


def test_a_model_that_never_answers_a_row_makes_the_verdict_late_and_incomplete(
    table: Path,
) -> None:
    """verdict_timeout_s after the last input the verdict comes without the missing row's
    prediction, and says which row it waited for."""
    _log, aggregator = _judged_beside_a_model(table, 2)
    assert aggregator.poll(1.1) is None  # the horizon reached, the wait starts: 5 s
    assert aggregator.poll(6.0) is None
    outcome = aggregator.poll(6.2)
    assert outcome is not None and not outcome.complete
    why = outcome.document["live"]["why_incomplete"]
    assert why == ["timed out waiting for the model's predicted paths: rows at 200 ms"], why
    assert outcome.document[TRAJECTORY_SCORES_KEY]["scored"] == 2
