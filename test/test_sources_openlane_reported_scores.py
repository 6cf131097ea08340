"""OpenLane-V2 scores reported by ``diagnose`` and the live perception monitor:
each frame's figures and the segment's so far in the not-judged perception result (corrected
mode), the segment's in the verdict JSON and the summary, the monitor's ``/diagnostics``
status, and a real DDS replay giving what diagnose gives.

The segment (7 frames, test/writers/openlane_segments.py) gets a model's results that vary
frame by frame: 0 perfect, 1 without the sign, 2 nothing at all (no annotation, no result:
nothing to score), 3 an empty result, 4 lane B 1.5 m to the left at confidence 0.6, 5 lane C
with a NaN point (the reader drops it), 6 no result (ground truth only).
"""

from __future__ import annotations

import contextlib
import json
import math
import subprocess
import sys
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pytest
from writers.openlane_segments import (
    predicted_annotation,
    write_openlane_predictions,
    write_openlane_segment,
)

from ads_rca.diagnosis.engine import diagnose
from ads_rca.diagnosis.summary import summary_text
from ads_rca.live.diagnostics import OK, STALE, result_status
from ads_rca.live.results import LiveResult
from ads_rca.live.simulate import run_live
from ads_rca.model import RunLog
from ads_rca.params import make_params
from ads_rca.sources.formats import SourceOptions
from ads_rca.sources.openlane.lanes import LaneGraph
from ads_rca.sources.openlane.reader import read_openlane_segment
from ads_rca.sources.openlane.run_scores import (
    BOTH,
    FRAME_KEY,
    INPUTS_KEY,
    OPENLANE_SCORES_KEY,
    PREDICTION_ONLY,
    RULES,
    SEGMENT_KEY,
    TRUTH_ONLY,
    LaneMatches,
    figures_text,
    frame_scores,
)
from ads_rca.sources.openlane.scores import score_frames

if TYPE_CHECKING:
    from conftest import RosEnv

ADS_RCA = str(Path(sys.executable).with_name("ads-rca"))
FRAMES = 7
NOTHING, EMPTY, GT_ONLY = 2, 3, 6
#: The frames scored: all but frame 2.
SCORED = [0, 1, 3, 4, 5, 6]


def info_files(segment: Path) -> list[Path]:
    return sorted((segment / "info").glob("*.json"))


def write_varied(root: Path) -> tuple[Path, Path]:
    """The segment and the model's results of the module docstring."""
    segment = write_openlane_segment(root / "data", frames=FRAMES)
    folder = root / "pred"
    folder.mkdir()
    files = info_files(segment)
    info = json.loads(files[NOTHING].read_text())
    del info["annotation"]
    files[NOTHING].write_text(json.dumps(info))
    shifted = fresh("perfect")
    shifted["lane_centerline"][1]["confidence"] = 0.6
    for point in shifted["lane_centerline"][1]["points"]:
        point[1] += 1.5
    broken = fresh("perfect")
    broken["lane_centerline"][2]["points"][1][0] = math.nan
    empty: dict[str, Any] = {"lane_centerline": [], "traffic_element": [], "topology_lclc": []}
    results: dict[int, dict[str, Any]] = {
        0: predicted_annotation("perfect"),
        1: predicted_annotation("missing_sign"),
        EMPTY: {**empty, "topology_lcte": []},
        4: shifted,
        5: broken,
    }
    for frame, result in results.items():
        (folder / files[frame].name).write_text(json.dumps({"predictions": result}))
    return segment, folder


def fresh(variant: str) -> dict[str, Any]:
    """A copy of a synthesised result to change (its points are the module's own lists)."""
    copied: dict[str, Any] = json.loads(json.dumps(predicted_annotation(variant)))
    return copied


@pytest.fixture
def varied(tmp_path: Path) -> tuple[Path, Path]:
    return write_varied(tmp_path)


def read(segment: Path, folder: Path | None = None) -> RunLog:
    source = SourceOptions(predictions=str(folder)) if folder is not None else SourceOptions()
    return read_openlane_segment(segment, source=source)


def pairs(log: RunLog) -> list[tuple[LaneGraph, LaneGraph]]:
    """Each scored frame's (ground truth, prediction), an absent prediction as an empty one."""
    stamps = [log.frames[i] for i in SCORED]
    return [(log.lanes[s], log.lanes_predicted.get(s, LaneGraph.empty())) for s in stamps]


def perception(document: dict[str, Any], frame: int) -> dict[str, Any]:
    result: dict[str, Any] = document["frames"][frame]["perception"]
    return result


# --- offline, against the scorer and by hand ---------------------------------------------


def test_each_frame_carries_its_figures_and_the_segment_so_far(varied: tuple[Path, Path]) -> None:
    log = read(*varied)
    document = diagnose(log, make_params("corrected")).to_json()
    scored = pairs(log)
    for n, frame in enumerate(SCORED):
        result = perception(document, frame)
        assert result[FRAME_KEY] == score_frames([scored[n]]).to_dict(), frame
        assert result[SEGMENT_KEY] == score_frames(scored[: n + 1]).to_dict(), frame
    assert document[OPENLANE_SCORES_KEY] == {
        **score_frames(scored).to_dict(),
        "semantics": "corrected",
        "rules": RULES,
    }
    # The scores are figures, not a verdict: perception stays not judged.
    assert document["modules_judged"]["perception"].startswith("not judged")
    assert document["modules"]["perception"] == {
        "collision": 0,
        "safe": 0,
        "first_failure_frame": None,
    }


def test_a_perfect_then_a_signless_frame_by_hand(varied: tuple[Path, Path]) -> None:
    document = diagnose(read(*varied), make_params("corrected")).to_json()
    first, second = perception(document, 0), perception(document, 1)
    assert first[INPUTS_KEY] == BOTH
    assert [first[FRAME_KEY][k] for k in ("ols", "det_l", "det_t", "top_ll", "top_lt")] == [1.0] * 5
    frame = second[FRAME_KEY]
    # Without the sign: DET_t = mean(red 1, go_straight 0) = 0.5. TOP_lt per vertex, each
    # threshold alike: lane A finds its light (1), lane B misses its sign (0), lane C gets a
    # false link to the unmatched sign (0), the light's column 1, the sign's 0: 2/5 = 0.4.
    assert frame["det_l"] == 1.0 and frame["det_t"] == 0.5 and frame["top_ll"] == 1.0
    assert frame["top_lt"] == pytest.approx(0.4)
    assert frame["ols"] == pytest.approx((1 + 0.5 + 1 + math.sqrt(0.4)) / 4)
    segment = second[SEGMENT_KEY]
    # Frames 0 and 1 pooled: go_straight 2 true, 1 found at precision 1: recall levels 0 to
    # 0.5 reached, 6/11; DET_t = (1 + 6/11) / 2 = 17/22. TOP_lt: 15 values of 1 and 15 of
    # mean 0.4: (15 + 6) / 30 = 0.7.
    assert segment["frames"] == 2
    assert segment["det_t"] == pytest.approx(17 / 22)
    assert segment["det_t_ap"] == {"red": 1.0, "go_straight": pytest.approx(6 / 11)}
    assert segment["top_lt"] == pytest.approx(0.7)
    assert segment["ols"] == pytest.approx((1 + 17 / 22 + 1 + math.sqrt(0.7)) / 4)


def test_ground_truth_without_a_prediction_is_all_missed(varied: tuple[Path, Path]) -> None:
    """An empty result and no result score alike: every lane and element missed (AP 0), every
    true link missing and every other entry a false link on unmatched lanes (TOP 0)."""
    document = diagnose(read(*varied), make_params("corrected")).to_json()
    for frame, held in ((EMPTY, BOTH), (GT_ONLY, TRUTH_ONLY)):
        result = perception(document, frame)
        assert result[INPUTS_KEY] == held
        figures = result[FRAME_KEY]
        assert [figures[k] for k in ("ols", "det_l", "det_t", "top_ll", "top_lt")] == [0.0] * 5
        assert figures["gt_lanes"] == 3 and figures["pred_lanes"] == 0
    # Frames 0, 1 and 3: 9 true lanes, 6 found at precision 1: recall 2/3 reaches the levels
    # 0 to 0.6, 7/11 at every threshold.
    assert perception(document, EMPTY)[SEGMENT_KEY]["det_l"] == pytest.approx(7 / 11)
    assert perception(document, GT_ONLY)[SEGMENT_KEY]["frames"] == len(SCORED)


def test_a_frame_with_nothing_to_score_has_no_figures(varied: tuple[Path, Path]) -> None:
    document = diagnose(read(*varied), make_params("corrected")).to_json()
    result = perception(document, NOTHING)
    assert not {FRAME_KEY, SEGMENT_KEY, INPUTS_KEY} & set(result)
    assert result["skipped"].startswith("not judged")


def test_nan_lanes_of_a_prediction_are_dropped_and_counted(varied: tuple[Path, Path]) -> None:
    log = read(*varied)
    stamp = log.frames[0]
    graph = log.lanes_predicted[stamp]
    bad = np.array([[0.0, 0.0, 0.0], [math.nan, 0.0, 0.0]])
    log.lanes_predicted[stamp] = replace(graph, lanes=(graph.lanes[0], bad, graph.lanes[2]))
    figures = frame_scores(log, stamp, LaneMatches())[FRAME_KEY]
    assert isinstance(figures, dict)
    assert figures["dropped_lanes"] == 1 and figures["pred_lanes"] == 2
    # Lanes A and C found, B missed: 2 of 3 at precision 1, recall levels 0 to 0.6: 7/11.
    assert figures["det_l"] == pytest.approx(7 / 11)
    # The reader drops a NaN point itself (frame 5), reported.
    reread = read(*varied)
    assert len(reread.lanes_predicted[reread.frames[5]].lanes) == 2
    assert any("lane_centerline[2]" in p.field for p in reread.problems)


def test_a_prediction_without_ground_truth_is_only_false_positives(
    varied: tuple[Path, Path],
) -> None:
    log = read(*varied)
    stamp = log.frames[0]
    del log.lanes[stamp]
    found = frame_scores(log, stamp, LaneMatches())
    figures = found[FRAME_KEY]
    assert found[INPUTS_KEY] == PREDICTION_ONLY and isinstance(figures, dict)
    # No ground truth: the lanes' and both classes' APs are 0; no topology to judge (null),
    # so OLS is undefined.
    assert figures["det_l"] == 0.0 and figures["det_t"] == 0.0
    assert figures["top_ll"] is None and figures["top_lt"] is None and figures["ols"] is None


def test_a_segment_without_a_models_results_scores_nothing(varied: tuple[Path, Path]) -> None:
    document = diagnose(read(varied[0]), make_params("corrected")).to_json()
    assert OPENLANE_SCORES_KEY not in document
    assert all(FRAME_KEY not in f["perception"] for f in document["frames"])
    assert "OpenLane-V2" not in summary_text(document)


def test_reference_mode_scores_nothing(varied: tuple[Path, Path]) -> None:
    """reference reproduces the reference tool: its perception rule judges the predicted
    elements as detections, and no OpenLane-V2 figure is added."""
    document = diagnose(read(*varied), make_params("reference")).to_json()
    assert OPENLANE_SCORES_KEY not in document
    assert all(FRAME_KEY not in f["perception"] for f in document["frames"])


def test_a_frame_is_matched_once(varied: tuple[Path, Path]) -> None:
    log = read(*varied)
    matches = LaneMatches()
    frame_scores(log, log.frames[4], matches)  # the earlier frames are matched first
    assert sorted(matches.by_stamp) == [log.frames[i] for i in (0, 1, 3, 4)]
    kept = matches.by_stamp[log.frames[1]]
    log.lanes_predicted[log.frames[1]] = LaneGraph.empty()  # too late: the match is kept
    again = frame_scores(log, log.frames[4], matches)
    assert matches.by_stamp[log.frames[1]] is kept
    assert again[SEGMENT_KEY] == score_frames(pairs(read(*varied))[:4]).to_dict()


def test_forked_workers_give_the_same_segment_figures(tmp_path: Path) -> None:
    """A worker matches the frames before its slice itself: 400 frames (the engine's
    parallel minimum) in two workers give one worker's results."""
    segment = write_openlane_segment(tmp_path / "data", frames=400)
    folder = write_openlane_predictions(tmp_path / "pred", segment, "missing_sign")
    for file in sorted(folder.glob("*.json"))[::3]:
        file.unlink()  # every third frame ground truth only, so the segment figures move
    log = read(segment, folder)
    params = make_params("corrected")
    alone, forked = diagnose(log, params).to_json(), diagnose(log, params, workers=2).to_json()
    assert forked["frames"] == alone["frames"]
    assert forked[OPENLANE_SCORES_KEY] == alone[OPENLANE_SCORES_KEY]
    assert alone[OPENLANE_SCORES_KEY]["frames"] == 400


# --- the command line --------------------------------------------------------------------


def test_diagnose_prints_and_writes_the_segment_figures(
    varied: tuple[Path, Path], tmp_path: Path
) -> None:
    segment, folder = varied
    out = tmp_path / "verdict.json"
    done = subprocess.run(
        [ADS_RCA, "diagnose", str(segment), "--predictions", str(folder), "--json", str(out)],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    document = json.loads(out.read_text())
    expected = score_frames(pairs(read(*varied)))
    assert document[OPENLANE_SCORES_KEY]["ols"] == expected.ols
    assert document[OPENLANE_SCORES_KEY]["rules"]["lane_frechet_thresholds_m"] == [1, 2, 3]
    assert document[OPENLANE_SCORES_KEY]["rules"]["element_iou_above"] == 0.25
    headline = figures_text(expected.to_dict())
    assert f"OpenLane-V2 scores (6 frames, semantics corrected): {headline}" in done.stdout
    assert f"OLS {expected.ols:.3f}, DET_l {expected.det_l:.3f}" in headline
    # 6 frames of 3 true lanes and 2 elements; predicted lanes 3 + 3 + 0 + 3 + 2 (one NaN
    # lane dropped) + 0 = 11, elements 2 + 1 + 0 + 2 + 2 + 0 = 7.
    assert "lanes 18 true / 11 predicted, traffic elements 12 / 7" in done.stdout
    assert "rules: Fréchet below 1, 2, 3 m, IoU above 0.25, links above 0.5" in done.stdout


def test_the_summary_survives_a_hostile_scores_document(varied: tuple[Path, Path]) -> None:
    document = diagnose(read(*varied), make_params("corrected")).to_json()
    document[OPENLANE_SCORES_KEY] = {
        "frames": "x",
        "ols": "1\n2",
        "det_l": math.nan,
        "det_l_ap": ["not", "a", "map"],
        "det_t_ap": {"\x1b[31mred": True},
    }
    text = summary_text(document)
    assert "OLS -, DET_l -, DET_t -, TOP_ll -, TOP_lt -" in text
    assert "DET_l AP: -; DET_t AP: " in text
    assert "\x1b" not in text


# --- live: the monitor core, its status, and a DDS replay --------------------------------


def expected_status(document: dict[str, Any], frame: int) -> tuple[int, str]:
    """The /diagnostics level and message of the perception status of a frame."""
    row = document["frames"][frame]
    result = row["perception"]
    if FRAME_KEY not in result:
        return STALE, f"frame {row['frame']}: no data: {result['skipped']}"
    segment = result[SEGMENT_KEY]
    count = segment["frames"]
    return OK, (
        f"frame {row['frame']}: OpenLane-V2 {figures_text(result[FRAME_KEY])} (frame) / "
        f"{figures_text(segment)} (segment so far, {count} frame{'' if count == 1 else 's'}); "
        f"the verdict rule: {result['skipped']}"
    )


@pytest.mark.parametrize("shared", [False, True], ids=["separate", "shared"])
def test_the_live_monitor_reports_what_diagnose_does(
    varied: tuple[Path, Path], shared: bool
) -> None:
    log = read(*varied)
    params = make_params("corrected")
    offline = diagnose(log, params).to_json()
    run = run_live(log, params, shared=shared)
    assert run.outcome is not None
    live = run.outcome.document
    assert live["frames"] == offline["frames"]
    assert live[OPENLANE_SCORES_KEY] == offline[OPENLANE_SCORES_KEY]
    results = run.results["perception"]
    assert [r.stamp_ms for r in results] == list(log.frames)
    for n, result in enumerate(results):
        status = result_status(result, "corrected", "test")
        assert (status.level, status.message) == expected_status(offline, n), n
    matches = LaneMatches.kept_in(run.monitors["perception"].scorer_state["lanes"])
    assert sorted(matches.by_stamp) == [log.frames[i] for i in SCORED]


def test_the_window_forgets_old_frames_but_the_segment_keeps_their_matches(
    tmp_path: Path,
) -> None:
    """60 frames with a short look-ahead and window: the monitor drops the records of judged
    frames, yet its last frame's segment figures pool all 60, as diagnose's do."""
    segment = write_openlane_segment(tmp_path / "data", frames=60)
    log = read(segment, write_openlane_predictions(tmp_path / "pred", segment, "missing_sign"))
    overrides = {"prediction_window": 1, "control_horizon": 1, "effect_time_window": 2}
    params = make_params("corrected", {**overrides, "window_s": 0.5})
    run = run_live(log, params)
    core = run.monitors["perception"]
    matches = LaneMatches.kept_in(core.scorer_state["lanes"])
    assert len(core.records["lanes"]) < 30 and len(matches.by_stamp) == 60
    assert run.outcome is not None
    live = run.outcome.document[OPENLANE_SCORES_KEY]
    assert live == diagnose(log, params).to_json()[OPENLANE_SCORES_KEY]
    assert live["frames"] == 60 and live["det_t"] == 0.5


def test_the_live_monitor_is_stale_without_a_models_results(varied: tuple[Path, Path]) -> None:
    run = run_live(read(varied[0]), make_params("corrected"))
    statuses = [result_status(r, "corrected", "t") for r in run.results["perception"]]
    assert [s.level for s in statuses] == [STALE] * FRAMES
    assert statuses[0].message.endswith("no data: not judged (no actors, plan, tracked_objects)")


def test_a_hostile_result_document_gives_a_status_not_a_traceback() -> None:
    document = {
        "module": "perception",
        "index": 3,
        "stamp_ms": 300,
        "frame": 3,
        "failed": False,
        "skipped": "not judged (no actors)",
        "metrics": {FRAME_KEY: "text", SEGMENT_KEY: {"frames": True, "ols": "0.5"}},
    }
    status = result_status(LiveResult.from_document(document), "corrected", "t")
    assert status.level == OK
    assert status.message == (
        "frame 3: OpenLane-V2 OLS -, DET_l -, DET_t -, TOP_ll -, TOP_lt - (frame) / OLS -, "
        "DET_l -, DET_t -, TOP_ll -, TOP_lt - (segment so far, - frames); the verdict rule: "
        "not judged (no actors)"
    )


def jsonl(path: Path) -> list[dict[str, Any]]:
    rows = []
    for line in path.read_text().splitlines() if path.exists() else []:
        with contextlib.suppress(ValueError):  # a line being written
            rows.append(json.loads(line))
    return rows


@pytest.mark.timeout(240)
def test_a_replay_over_dds_reports_what_diagnose_does(
    ros_env: RosEnv, varied: tuple[Path, Path], tmp_path: Path
) -> None:
    """Player, monitors and aggregator over DDS: the verdict's frames (each frame's figures
    and the segment's so far) and segment figures are diagnose's, and every perception
    status on /diagnostics says its frame's figures (OK) or no data (STALE)."""
    from rosrun import wait_for

    from ads_rca.ros.launcher import ManagedProcess

    segment, folder = varied
    out, diagnostics = tmp_path / "verdict.json", tmp_path / "diagnostics.jsonl"
    last = str(read(segment).frames[-1])
    probe_script = Path(__file__).parent / "diag_probe.py"
    probe = ManagedProcess(
        "probe", [sys.executable, str(probe_script), str(diagnostics)], ros_env.env
    )
    try:
        wait_for(lambda: "probe ready" in probe.output, 20, "the probe")
        argv = [sys.executable, "-m", "ads_rca.cli", "replay", str(segment), "--json", str(out)]
        argv += ["--predictions", str(folder), "--semantics", "corrected", "--rate", "1"]
        # A look-ahead of one frame (10 by default: the whole segment), so the monitor judges
        # each frame when the next arrives and sends a status per frame.
        argv += ["-p", "prediction_window=1", "-p", "control_horizon=1"]
        argv += ["--domain-id", str(ros_env.domain_id), "--timeout", "90"]
        replay = ManagedProcess("replay", argv, ros_env.env)
        assert replay.wait(150) == 0, replay.output
        statuses = wait_for(
            lambda: [
                row
                for row in jsonl(diagnostics)
                if row["name"] == "ads_rca/perception" and row["values"].get("stamp_ms") == last
            ],
            10,
            "the last frame's perception status",
        )
    finally:
        probe.stop()
    live = json.loads(out.read_text())
    params = make_params("corrected", {"prediction_window": 1, "control_horizon": 1})
    offline = diagnose(read(*varied), params).to_json()
    assert live["frames"] == offline["frames"]
    assert live[OPENLANE_SCORES_KEY] == offline[OPENLANE_SCORES_KEY]
    assert statuses[-1]["level"] == OK
    assert f"(segment so far, {len(SCORED)} frames)" in statuses[-1]["message"]
    stamps = [f["timestamp_ms"] for f in offline["frames"]]
    seen = [
        r
        for r in jsonl(diagnostics)
        if r["name"] == "ads_rca/perception" and "stamp_ms" in r["values"]
    ]
    # One status per batch of judged frames (its latest frame); frames 0.5 s apart with a
    # look-ahead of one frame come one by one unless the machine is slow.
    assert len(seen) >= 2, seen
    for row in seen:
        frame = stamps.index(int(row["values"]["stamp_ms"]))
        assert (row["level"], row["message"]) == expected_status(offline, frame), frame
    assert {stamps.index(int(r["values"]["stamp_ms"])) for r in seen if r["level"] == STALE} <= {
        NOTHING
    }
