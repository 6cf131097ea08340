"""A live trajectory-prediction model beside a playing table, over DDS: its own
process (test/ego_path_model.py) hears each row the player sends on ``run/ego_paths`` and
answers with the realised path shifted 1 m in x; the planning monitor scores each row with
the model's path frame by frame (``metrics/planning``, ``/diagnostics``), and the verdict's
trajectory scores agree.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
from writers.atmacup_tables import ROWS, write_table

from ads_rca.ros.launcher import ManagedProcess
from ads_rca.sources.atmacup.trajectory_scores import TRAJECTORY_SCORES_KEY

if TYPE_CHECKING:
    from conftest import RosEnv

IDS = [row.ident for row in ROWS]
MODEL = Path(__file__).with_name("ego_path_model.py")


def recorded(bag: Path) -> tuple[list[dict[str, Any]], list[Any]]:
    """The bag's planning results (JSON) and its ``ads_rca/planning`` statuses."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    results: list[dict[str, Any]] = []
    statuses: list[Any] = []
    with next(bag.glob("*.mcap")).open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _schema, channel, _raw, msg in reader.iter_decoded_messages(log_time_order=True):
            if channel.topic.endswith("/metrics/planning"):
                results.append(json.loads(msg.data))
            elif channel.topic == "/diagnostics":
                statuses += [s for s in msg.status if s.name == "ads_rca/planning"]
    return results, statuses


def recorded_statuses(bag: Path, name: str) -> list[Any]:
    """The bag's ``/diagnostics`` statuses called ``name``, in order."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    out: list[Any] = []
    with next(bag.glob("*.mcap")).open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _schema, _channel, _raw, msg in reader.iter_decoded_messages(
            topics=["/diagnostics"], log_time_order=True
        ):
            out += [s for s in msg.status if s.name == name]
    return out


def replay_beside(
    ros_env: RosEnv, tmp_path: Path, *model_args: str
) -> tuple[ManagedProcess, Path, Path]:
    """The graph (recorder, aggregator, monitors, player) playing the table (no submission:
    the player's rows carry no predicted path), its player waiting for the test model too;
    the model, the bag and the verdict JSON."""
    from ads_rca.params import make_params
    from ads_rca.ros.graph import Graph, GraphSpec
    from ads_rca.sources.formats import SourceOptions

    table = tmp_path / "data"
    write_table(table)
    bag, out = tmp_path / "bag", tmp_path / "verdict.json"
    spec = GraphSpec(
        log_path=table,
        params=make_params("corrected"),
        verdict_json=out,
        namespace=ros_env.namespace,
        rate=0.25,  # rows 400 ms apart: the model's first answer comes well before the
        # monitors' last results, so the aggregator knows a model answers and waits for it
        record=bag,
        player_params={**SourceOptions().as_params()},
    )
    waited = len(spec.nodes()) - 1  # every node but the player subscribes to run/frame
    spec.player_params["wait_for_subscribers"] = waited + 1  # and the model
    argv = [sys.executable, str(MODEL), "--namespace", ros_env.namespace, *model_args]
    argv += ["--run-id", spec.run_id, "--subscribers", "4"]  # itself, recorder, aggregator,
    model = ManagedProcess("model", argv, ros_env.env)  # monitors
    try:
        with Graph(spec, ros_env.env) as graph:
            graph.start()
            assert graph.wait_verdict(120) is not None, graph.failed()
            time.sleep(1.0)  # a late answer's result, published before the monitors stop
            graph.stop()
    finally:
        model.stop(timeout=5.0)
    assert "answered" in model.output, model.output
    return model, bag, out


def latest_rows(results: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Each frame's result of the highest revision (the aggregator's and recorder's rule)."""
    latest: dict[int, dict[str, Any]] = {}
    for result in results:
        held = latest.get(result["stamp_ms"])
        if held is None or result["revision"] >= held["revision"]:
            latest[result["stamp_ms"]] = result
    return [latest[stamp] for stamp in sorted(latest)]


def assert_shift_scored(rows: list[dict[str, Any]]) -> None:
    """Hand arithmetic: each horizon's point is 1 m off in x alone, so every distance is
    1 m: ADE = FDE = 1.0 per row; MAE = six x errors of 1 over 18 values = 1/3."""
    assert [r["metrics"]["row_id"] for r in rows] == IDS, rows
    for r in rows:
        assert r["metrics"]["trajectory_ade"] == pytest.approx(1.0)
        assert r["metrics"]["trajectory_fde"] == pytest.approx(1.0)
        assert r["metrics"]["trajectory_mae"] == pytest.approx(1 / 3)


def test_a_live_models_paths_are_scored_frame_by_frame_and_in_the_verdict(
    ros_env: RosEnv, tmp_path: Path
) -> None:
    """A model answering each row as it hears it: the monitor scores each row with the
    model's path (judged with it, or, when it came after the row was judged, scored again
    with a higher revision), and the verdict scores the same paths. Before each answer the
    model sends no JSON, a path 1e300 m away and a path 5 m off naming another run: the
    first two are skipped and counted, the third dropped by the run filter; none moves a
    score."""
    _model, bag, out = replay_beside(ros_env, tmp_path, "--hostile")
    results, statuses = recorded(bag)
    skipped = [
        int(value.value)
        for status in recorded_statuses(bag, "ads_rca/planning/monitor")
        for value in status.values
        if value.key == "skipped_messages"
    ]
    assert skipped and max(skipped) >= 2 * len(IDS), skipped
    rows = latest_rows(results)
    assert_shift_scored(rows)
    scored = [s.message for s in statuses if "predicted path scored" in s.message]
    assert scored and all("ADE 1.00 m, FDE 1.00 m" in m for m in scored), scored
    verdict = json.loads(out.read_text())
    scores = verdict[TRAJECTORY_SCORES_KEY]
    assert scores["submission"] == "shift-model" and scores["scored"] == 3
    assert scores["per_row"]["ids"] == IDS
    assert scores["per_row"]["ade"] == [r["metrics"]["trajectory_ade"] for r in rows]
    assert scores["mae"] == pytest.approx(1 / 3) and scores["ade"] == pytest.approx(1.0)
    # The verdict's frames hold the results in when it was rendered: a row the monitor had
    # judged before the model's path came may still be its first, unscored result there.
    for frame in verdict["frames"]:
        assert frame["planning"].get("trajectory_ade", 1.0) == pytest.approx(1.0)


def test_a_model_answering_after_the_monitor_judged_is_scored_again(
    ros_env: RosEnv, tmp_path: Path
) -> None:
    """A slow model answers each row only after the planning monitor's first result for it
    is out (with no prediction: nothing scored): the monitor publishes each row's planning
    result again, revision 1, scoring the model's path. (The verdict is rendered once the
    last frame's first results are in, so an answer this late may miss it: not asserted.)"""
    _model, bag, _out = replay_beside(ros_env, tmp_path, "--after-result")
    results, statuses = recorded(bag)
    first = [r for r in results if r["revision"] == 0]
    assert [r["stamp_ms"] for r in first] == [0, 100, 200]
    assert all("row_id" not in r["metrics"] for r in first)  # judged before the answer
    rows = latest_rows(results)
    assert [r["revision"] for r in rows] == [1, 1, 1]
    assert_shift_scored(rows)
    assert any("ADE 1.00 m, FDE 1.00 m" in s.message for s in statuses)
