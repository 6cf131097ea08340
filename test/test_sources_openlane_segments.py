"""OpenLane-V2 segments: every field of the synthesised segments
(test/writers/openlane_segments.py) as worked out by hand — nanosecond and microsecond
timestamps, integer and text ids, the mirrored pose and its angles, the derived speed, the
traffic elements as boxes, lanes mirrored with their topology — a model's per-frame results,
format detection, hostile files and entries, and the command line.
"""

from __future__ import annotations

import json
import math
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pytest
from commandline import run_script
from writers.openlane_segments import (
    NS_START,
    US_START,
    rotation,
    write_openlane_predictions,
    write_openlane_segment,
)

from ads_rca.diagnosis.engine import diagnose
from ads_rca.errors import InputError
from ads_rca.model import RunLog
from ads_rca.params import make_params
from ads_rca.sources.formats import SourceOptions
from ads_rca.sources.openlane.reader import ego_poses, read_openlane_segment, timestamp_unit
from ads_rca.sources.registry import detect_format, open_run

if TYPE_CHECKING:
    from conftest import RosEnv

ADS_RCA = str(Path(sys.executable).with_name("ads-rca"))
FRAMES = 6
#: Frames count from the segment's first stamp (315967376859927000 ns in the ns segment,
#: 1531883530412470 µs in the µs one, kept as the metadata's segment.first_timestamp), so
#: either segment's first frame is at 0 ms, not at the epoch's 315967376860 ms.
NS_FIRST_MS = 0
US_FIRST_MS = 0


def problems_of(log: RunLog) -> list[str]:
    return [f"{p.file} {p.field}: {p.issue} ({p.action})" for p in log.problems]


def info_files(segment: Path) -> list[Path]:
    return sorted((segment / "info").glob("*.json"))


def edit(segment: Path, frame: int, change: Callable[[dict[str, Any]], object]) -> Path:
    """Frame ``frame``'s info document changed in place by ``change``; its file."""
    file = info_files(segment)[frame]
    document = json.loads(file.read_text())
    change(document)
    file.write_text(json.dumps(document))
    return file


@pytest.fixture
def segment(tmp_path: Path) -> Path:
    return write_openlane_segment(tmp_path / "data", frames=FRAMES)


# --- the mapping, by hand ----------------------------------------------------------------


def test_every_field_maps_as_worked_out_by_hand(segment: Path) -> None:
    log = read_openlane_segment(segment)
    assert problems_of(log) == []
    # 0.5 s apart: 500 ms steps from the rounded first stamp.
    assert log.frames == tuple(NS_FIRST_MS + 500 * n for n in range(FRAMES))
    assert log.frame_ms == 500 and log.metadata.collision_frame == -1
    first, second = log.pose[log.frames[0]], log.pose[log.frames[1]]
    # (100, 200, 5) mirrored; Rz(30°) Ry(2°) Rx(1°): roll kept, pitch and yaw negated.
    assert (first.x, first.y, first.z) == (100.0, -200.0, 5.0)
    assert (first.roll, first.pitch, first.yaw) == pytest.approx((1.0, -2.0, -30.0))
    # 10 m/s for 0.5 s along 30°: +5 cos 30° = 4.330127 in x, +5 sin 30° = 2.5 in y (mirrored).
    assert (second.x, second.y) == pytest.approx((104.330127, -202.5))
    assert first.speed == pytest.approx(10.0) and second.speed == pytest.approx(10.0)
    boxes = log.bboxes_gt[log.frames[0]]
    assert boxes.ids == ("10", "11")
    assert boxes.corners.tolist() == [[100.0, 200.0, 120.0, 260.0], [300.0, 100.0, 340.0, 140.0]]
    assert boxes.extras == (
        {"label": "red", "category": "traffic_light", "attribute": "red"},
        {"label": "go_straight", "category": "road_sign", "attribute": "go_straight"},
    )
    assert log.bboxes == {} and log.actors == {} and log.waypoints == {}


def test_lanes_are_mirrored_and_their_topology_kept(segment: Path) -> None:
    log = read_openlane_segment(segment)
    graph = log.lanes[log.frames[0]]
    assert graph.lane_ids == ("1", "2", "3") and graph.element_ids == ("10", "11")
    # Every released point is kept (the scores thin the ground truth, not the reader).
    # B at y = 3.5 left is y = -3.5 in the model; C's (25, 1.5) is (25, -1.5).
    assert [len(lane) for lane in graph.lanes] == [201, 201, 201]
    assert graph.lanes[1][::100].tolist() == [
        [0.0, -3.5, 0.0],
        [10.0, -3.5, 0.0],
        [20.0, -3.5, 0.0],
    ]
    assert graph.lanes[2][100].tolist() == [25.0, -1.5, 0.0]
    assert graph.lane_lane.tolist() == [[0, 0, 1], [0, 0, 0], [0, 0, 0]]
    assert graph.lane_element.tolist() == [[1, 0], [0, 1], [0, 0]]
    assert np.isnan(graph.lane_scores).all() and np.isnan(graph.element_scores).all()
    assert graph.element_category.tolist() == [1, 2]
    assert graph.element_attribute.tolist() == [1, 4]
    assert set(log.lanes) == set(log.frames) and log.lanes_predicted == {}


def test_a_microsecond_segment_with_text_ids(tmp_path: Path) -> None:
    segment = write_openlane_segment(tmp_path, "01000", unit="us", text_ids=True)
    log = read_openlane_segment(segment)
    assert problems_of(log) == []
    assert log.frames[0] == US_FIRST_MS and log.frame_ms == 500
    assert log.metadata.raw["timestamp_unit"] == "us"
    graph = log.lanes[log.frames[0]]
    assert graph.lane_ids == ("lane-1", "lane-2", "lane-3")
    assert log.bboxes_gt[log.frames[0]].ids == ("te-10", "te-11")
    assert log.pose[log.frames[1]].speed == pytest.approx(10.0)


def test_the_unit_is_told_by_magnitude() -> None:
    assert timestamp_unit([NS_START]) == "ns" and timestamp_unit([US_START]) == "us"
    assert timestamp_unit([10**17]) == "ns" and timestamp_unit([10**17 - 1]) == "us"
    assert timestamp_unit([10**14 - 1]) is None and timestamp_unit([]) is None
    # The median decides: one odd file among three does not.
    assert timestamp_unit([US_START, NS_START, US_START + 1]) == "us"


def test_millisecond_names_are_not_a_segment(tmp_path: Path) -> None:
    info = tmp_path / "seg" / "info"
    info.mkdir(parents=True)
    (info / "1700000000000.json").write_text("{}")
    with pytest.raises(InputError, match=r"neither nanoseconds .* nor microseconds"):
        read_openlane_segment(info.parent)


def test_rotations_mirror_as_worked_out_by_hand() -> None:
    # Facing the city's +y (yaw 90° counter-clockwise): the model's -y, yaw -90.
    # Nose up 10°: forward = (cos 10°, 0, sin 10°), so R20 = sin 10° and the right-handed
    # pitch asin(-R20) = -10°; the model's pitch (nose up positive) is +10.
    # Right side down 5° (Rx(5°) takes y-left up): roll stays +5.
    rotations = np.array([rotation(90.0, 0.0, 0.0), rotation(0.0, -10.0, 0.0), rotation(0, 0, 5)])
    translations = np.array([[0.0, 0.0, 0.0], [0.0, 3.0, 0.0], [4.0, 3.0, 0.0]])
    poses = ego_poses(rotations, translations, [0, 1000, 1500])
    assert (poses[0].roll, poses[0].pitch, poses[0].yaw) == pytest.approx((0.0, 0.0, -90.0))
    assert (poses[1].roll, poses[1].pitch, poses[1].yaw) == pytest.approx((0.0, 10.0, 0.0))
    assert (poses[2].roll, poses[2].pitch, poses[2].yaw) == pytest.approx((5.0, 0.0, 0.0))
    # 3 m in 1 s, then 4 m in 0.5 s; the first frame takes the next difference.
    assert [p.speed for p in poses] == pytest.approx([3.0, 3.0, 8.0])
    assert [p.y for p in poses] == [0.0, -3.0, -3.0]
    assert not any(math.copysign(1.0, p.yaw) < 0 for p in poses[1:])  # no -0.0


def test_one_frame_has_no_speed(segment: Path) -> None:
    for file in info_files(segment)[1:]:
        file.unlink()
    log = read_openlane_segment(segment)
    assert log.frames == (NS_FIRST_MS,) and log.frame_ms == 500
    assert math.isnan(log.pose[NS_FIRST_MS].speed)


def test_the_capability_record_and_metadata(segment: Path) -> None:
    log = read_openlane_segment(segment)
    states = {name: status.state for name, status in log.inputs.items()}
    assert states["ego"] == "derived" and "speed derived" in log.inputs["ego"].reason
    assert states["ground_truth_2d"] == "real"
    assert {n for n, s in states.items() if s == "absent"} == set(states) - {
        "ego",
        "ground_truth_2d",
    }
    raw = log.metadata.raw
    assert raw["source_format"] == "openlane" and raw["timestamp_unit"] == "ns"
    assert "y' = -y" in raw["source_frame"] and "pitch' = -pitch" in raw["source_frame"]
    assert raw["segment"]["id"] == "00492" and raw["segment"]["source"] == "av2"
    assert raw["segment"]["first_timestamp"] == NS_START
    document = diagnose(log, make_params("corrected")).to_json()
    assert all(v.startswith("not judged") for v in document["modules_judged"].values())
    # A perception benchmark records no collision: unknown, never "no collision".
    assert document["verdict"].startswith(
        "inconclusive: collision unknown (a perception benchmark: no collision recorded)"
    )
    assert document["collision"] == "unknown" and document["conclusive"] is False
    assert document["input_problems"] == []


def test_segment_text_is_bounded_and_never_trusted(segment: Path) -> None:
    for n in range(FRAMES):
        edit(segment, n, lambda d: d.update(segment_id="\x1b[2Jevil", version="v" * 500))
    raw = read_openlane_segment(segment).metadata.raw
    assert raw["segment"]["segment_id"] == "" and raw["segment"]["version"] == "v" * 64


# --- the path and its format -------------------------------------------------------------


def test_auto_detects_a_segment_its_info_folder_and_a_dataset_root(segment: Path) -> None:
    root = segment.parent.parent
    (root / "data_dict_sample.json").write_text("{}")
    assert detect_format(segment) == detect_format(segment / "info") == "openlane"
    assert detect_format(root) == "openlane"
    assert open_run(segment / "info").frames == open_run(segment).frames
    log_folder = root / "log"
    (log_folder / "actors").mkdir(parents=True)
    (log_folder / "info").mkdir()
    (log_folder / "info" / "1.json").write_text("{}")
    assert detect_format(log_folder) == "log"


def test_detection_never_opens_a_file(segment: Path) -> None:
    fifo = segment / "info" / f"{NS_START + 9 * 500_000_000}.json"
    os.mkfifo(fifo)
    assert detect_format(segment) == "openlane"
    log = read_openlane_segment(segment)  # the FIFO is refused, not read (it would block)
    assert any("FIFO" in p for p in problems_of(log)) and len(log.frames) == FRAMES


def test_a_dataset_root_is_one_line_naming_its_segments(segment: Path, tmp_path: Path) -> None:
    root = segment.parent.parent
    write_openlane_segment(root, "00556")
    write_openlane_segment(root, "10000", split="val")
    (root / "data_dict_sample.json").write_text("{}")
    with pytest.raises(InputError) as error:
        open_run(root)
    message = str(error.value)
    assert "\n" not in message
    assert "3 segments (train/00492, train/00556, val/10000)" in message
    assert "give one segment folder" in message
    with pytest.raises(InputError, match="2 segments"):
        read_openlane_segment(root / "train")
    with pytest.raises(InputError, match=r"no info/ folder"):
        read_openlane_segment(tmp_path)


def test_a_split_folder_in_auto_is_one_line_naming_its_segments(segment: Path) -> None:
    """Issue 39 item 4: ``--format auto`` on ``val/`` said "not an ADS running log"."""
    split = segment.parent
    write_openlane_segment(split.parent, "00556")
    assert detect_format(split) == "openlane"
    with pytest.raises(InputError) as error:
        open_run(split)
    message = str(error.value)
    assert "\n" not in message and "2 segments (00492, 00556)" in message
    done = run_script("diagnose", str(split))
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.count("\n") == 1 and "2 segments (00492, 00556)" in done.stderr


# --- a model's results -------------------------------------------------------------------


@pytest.mark.parametrize("wrap", ["predictions", "annotation", "bare"])
def test_a_models_results_are_detections_and_predicted_lanes(
    segment: Path, tmp_path: Path, wrap: str
) -> None:
    folder = write_openlane_predictions(tmp_path / "pred", segment, "perfect", wrap)
    log = open_run(segment, source=SourceOptions(predictions=str(folder)))
    assert problems_of(log) == []
    assert set(log.lanes_predicted) == set(log.bboxes) == set(log.frames)
    boxes = log.bboxes[log.frames[2]]
    assert boxes.ids == ("100", "101") and [e["score"] for e in boxes.extras] == [0.9, 0.9]
    assert boxes.corners.tolist() == log.bboxes_gt[log.frames[2]].corners.tolist()
    graph = log.lanes_predicted[log.frames[2]]
    assert graph.lane_ids == ("p0", "p1", "p2") and graph.lane_scores.tolist() == [0.9] * 3
    assert graph.lane_lane.tolist() == [[0.1, 0.1, 0.8], [0.1, 0.1, 0.1], [0.1, 0.1, 0.1]]
    assert graph.lanes[1][0].tolist() == [0.0, -3.5, 0.0]
    assert log.inputs["detections_2d"].state == "real"
    assert log.inputs["detections_2d"].source == str(folder)
    assert log.metadata.raw["model_inputs"]["detections_2d"]["state"] == "real"


def test_a_result_missing_the_sign_keeps_its_shape(segment: Path, tmp_path: Path) -> None:
    folder = write_openlane_predictions(tmp_path / "pred", segment, "missing_sign")
    log = read_openlane_segment(segment, source=SourceOptions(predictions=str(folder)))
    graph = log.lanes_predicted[log.frames[0]]
    assert graph.element_ids == ("100",) and graph.lane_element.shape == (3, 1)
    assert graph.lane_element[:, 0].tolist() == [0.8, 0.1, 0.1]
    assert len(log.bboxes[log.frames[0]]) == 1


def test_reference_mode_judges_perception_on_predicted_elements(
    segment: Path, tmp_path: Path
) -> None:
    folder = write_openlane_predictions(tmp_path / "pred", segment, "perfect")
    log = read_openlane_segment(segment, source=SourceOptions(predictions=str(folder)))
    document = diagnose(log, make_params("reference")).to_json()
    assert document["modules_judged"]["perception"] == "judged"
    # A perception benchmark records no collision: unknown, never "no collision".
    assert document["verdict"].startswith(
        "inconclusive: collision unknown (a perception benchmark: no collision recorded)"
    )
    assert document["collision"] == "unknown" and document["conclusive"] is False


def test_bad_result_files_are_reported_and_the_rest_read(segment: Path, tmp_path: Path) -> None:
    folder = write_openlane_predictions(tmp_path / "pred", segment, "perfect")
    files = sorted(folder.glob("*.json"))
    files[0].write_text('{"predictions": {"lane_centerline": [')  # cut
    files[1].write_text('{"something": 1}')
    files[2].unlink()
    (folder / f"{NS_START + 99 * 500_000_000}.json").write_text("{}")
    (folder / "README.json").write_text("{}")
    document = json.loads(files[3].read_text())
    document["predictions"]["traffic_element"][0]["confidence"] = "0.9"
    document["predictions"]["lane_centerline"][1]["confidence"] = math.nan
    files[3].write_text(json.dumps(document))
    log = read_openlane_segment(segment, source=SourceOptions(predictions=str(folder)))
    found = problems_of(log)
    assert any(files[0].name in p and "invalid JSON" in p for p in found), found
    assert any(files[1].name in p and "expected an annotation object" in p for p in found)
    assert any("1 prediction files name no frame" in p for p in found)
    assert any("pred/README.json file name: not <timestamp>.json" in p for p in found), found
    assert any("3 frames have no usable prediction" in p for p in found)
    assert any("traffic_element[0].confidence: '0.9' is not a finite number" in p for p in found)
    assert any("lane_centerline[1].confidence: nan is not a finite number" in p for p in found)
    fourth = log.lanes_predicted[log.frames[3]]
    # The lane and the element dropped with their rows and columns of the topology.
    assert fourth.lane_ids == ("p0", "p2") and fourth.element_ids == ("101",)
    assert fourth.lane_lane.tolist() == [[0.1, 0.8], [0.1, 0.1]]
    assert fourth.lane_element.tolist() == [[0.1], [0.1]]
    assert set(log.lanes_predicted) == set(log.frames[3:])


def test_predictions_elsewhere_or_missing_are_one_line(segment: Path, tmp_path: Path) -> None:
    with pytest.raises(InputError, match="no such folder of prediction files"):
        open_run(segment, source=SourceOptions(predictions=str(tmp_path / "none")))
    log_folder = tmp_path / "log"
    (log_folder / "actors").mkdir(parents=True)
    with pytest.raises(InputError, match=r"OpenLane-V2 segments .*not to a running log"):
        open_run(log_folder, source=SourceOptions(predictions=str(tmp_path)))
    with pytest.raises(InputError, match="ego_agent applies to DLP scenes"):
        open_run(segment, source=SourceOptions(ego_agent="1"))


# --- hostile input -----------------------------------------------------------------------


def test_a_cut_or_corrupt_info_file_skips_its_frame(segment: Path) -> None:
    files = info_files(segment)
    files[1].write_bytes(files[1].read_bytes()[:200])
    files[2].write_text("[1, 2]")
    files[3].write_text("")
    log = read_openlane_segment(segment)
    found = problems_of(log)
    assert any(f"info/{files[1].name}" in p and "invalid JSON" in p for p in found), found
    assert any(
        f"info/{files[2].name}" in p and "expected an object, found list" in p for p in found
    )
    assert any(f"info/{files[3].name}" in p and "empty file" in p for p in found)
    assert len(log.frames) == FRAMES - 3
    # The speed across the skipped frames: 10 m/s held (5 m per 0.5 s, 20 m over 2 s).
    assert log.pose[log.frames[1]].speed == pytest.approx(10.0)


def test_a_missing_or_unusable_pose_skips_its_frame(segment: Path) -> None:
    edit(segment, 1, lambda d: d.pop("pose"))
    edit(segment, 2, lambda d: d["pose"].update(translation=["100", 200, 5]))
    edit(segment, 3, lambda d: d["pose"].update(rotation=[[1, 0], [0, 1]]))
    log = read_openlane_segment(segment)
    found = [p for p in problems_of(log) if " pose: " in p]
    assert len(found) == 3 and all("frame skipped" in p for p in found), found
    assert "missing" in found[0] and "no finite 3x3 rotation" in found[1]
    assert len(log.frames) == FRAMES - 3


def test_a_rotation_that_is_not_one(segment: Path) -> None:
    def scaled(factor: float) -> Callable[[dict[str, Any]], None]:
        return lambda d: d["pose"].update(
            rotation=(np.array(d["pose"]["rotation"]) * factor).tolist()
        )

    edit(segment, 1, scaled(1.01))  # RᵀR = 1.0201 I: used, reported
    edit(segment, 2, scaled(2.0))  # RᵀR = 4 I: skipped
    edit(segment, 3, lambda d: d["pose"].update(rotation=np.diag([1.0, -1.0, 1.0]).tolist()))
    log = read_openlane_segment(segment)
    found = [p for p in problems_of(log) if "pose.rotation" in p]
    assert len(found) == 3, found
    assert "0.0201" in found[0] and "value kept" in found[0]
    assert "frame skipped" in found[1] and "det -1" in found[2] and "frame skipped" in found[2]
    assert len(log.frames) == FRAMES - 2
    assert log.pose[log.frames[1]].yaw == pytest.approx(-30.0)  # the scale cancels in atan2


def test_a_timestamp_that_disagrees_with_its_file_name(segment: Path) -> None:
    edit(segment, 2, lambda d: d.update(timestamp=12345))
    log = read_openlane_segment(segment)
    found = [p for p in problems_of(log) if " timestamp: " in p]
    assert len(found) == 1 and "12345 is not the file name's" in found[0], found
    assert "the file name's kept" in found[0]
    assert log.frames == tuple(NS_FIRST_MS + 500 * n for n in range(FRAMES))


def test_frames_count_from_the_first_listed_stamp_even_when_its_file_is_unusable(
    segment: Path, tmp_path: Path
) -> None:
    """The origin is the first timestamp listed in the segment's unit, not the first usable
    frame: a cut first file leaves frame 0 out (reported) and the others where they were,
    and a model's results, named by the dataset's stamps, land on the same frames."""
    predictions = write_openlane_predictions(tmp_path / "pred", segment)
    info_files(segment)[0].write_text('{"pose": ')
    log = read_openlane_segment(segment, source=SourceOptions(predictions=str(predictions)))
    assert log.frames == tuple(500 * n for n in range(1, FRAMES))
    assert log.metadata.raw["segment"]["first_timestamp"] == NS_START
    assert set(log.lanes_predicted) == set(log.frames)
    assert any(p.startswith(f"info/{NS_START}.json") for p in problems_of(log))


def test_gaps_are_reported_as_the_running_log_reader_does(segment: Path) -> None:
    info_files(segment)[2].unlink()
    info_files(segment)[2].unlink()  # frames 2 and 3
    log = read_openlane_segment(segment)
    found = [p for p in problems_of(log) if "gap" in p]
    start = NS_FIRST_MS + 500
    assert found == [
        f"info/ timestamp: gap: no frame between {start} and {start + 1500} ms (about 2 "
        "missing) (frames around the gap are analysed; the speed across it is an average)"
    ]
    assert log.frame_ms == 500


def test_varying_steps_are_no_gap(tmp_path: Path) -> None:
    segment = write_openlane_segment(tmp_path, "01000", unit="us")
    last = info_files(segment)[-1]
    last.rename(last.with_name(f"{int(last.stem) + 150_000}.json"))  # 650 ms after the one before
    log = read_openlane_segment(segment)
    assert not any("gap" in p for p in problems_of(log)) and log.frame_ms == 500


def test_bad_lanes_and_elements_are_dropped_with_their_topology(segment: Path) -> None:
    def damage(document: dict[str, Any]) -> None:
        annotation = document["annotation"]
        annotation["lane_centerline"][0]["points"][1][1] = "0"  # text number
        annotation["lane_centerline"].append({"id": 2, "points": [[0, 0, 0], [1, 0, 0]]})
        annotation["topology_lclc"] = [[0, 0, 1, 0], [0, 0, 1, 1], [0, 0, 0, 0], [0, 1, 0, 0]]
        annotation["topology_lcte"] = [[1, 0, 0], [0, 1, 0], [1, 0, 0], [1, 1, 1]]
        annotation["traffic_element"][1]["attribute"] = 13
        annotation["traffic_element"].append({"id": True, "category": 1, "attribute": 1})

    edit(segment, 0, damage)
    log = read_openlane_segment(segment)
    found = problems_of(log)
    assert any("lane_centerline[0].points: not [n >= 2][3] finite numbers" in p for p in found)
    assert any("lane_centerline[3].id: 2 repeats an earlier id" in p for p in found), found
    assert any("traffic_element[1].attribute: 13 is not 0 to 12" in p for p in found)
    assert any("traffic_element[2].id: True is not an integer" in p for p in found)
    graph = log.lanes[log.frames[0]]
    assert graph.lane_ids == ("2", "3") and graph.element_ids == ("10",)
    # Lanes 1 and 2 of the file's four kept (rows and columns 1, 2 of its 4x4 matrix:
    # [[0, 1], [0, 0]]), element 0 of its three (rows 1, 2 of column 0: 0, 1).
    assert graph.lane_lane.tolist() == [[0, 1], [0, 0]]
    assert graph.lane_element.tolist() == [[0], [1]]
    assert log.bboxes_gt[log.frames[0]].ids == ("10",)


def test_a_topology_of_the_wrong_shape_is_no_links(segment: Path) -> None:
    edit(segment, 0, lambda d: d["annotation"].update(topology_lclc=[[0, 1], [1, 0]]))
    edit(segment, 1, lambda d: d["annotation"].update(topology_lcte=[[1, 0], [0]]))
    edit(segment, 2, lambda d: d["annotation"].update(topology_lcte="none"))
    log = read_openlane_segment(segment)
    found = problems_of(log)
    assert any("topology_lclc: shape (2, 2), expected (3, 3)" in p for p in found), found
    assert any("topology_lcte: not a rectangular matrix, expected (3, 2)" in p for p in found)
    assert any("topology_lcte: expected a matrix, found str" in p for p in found)
    assert not log.lanes[log.frames[0]].lane_lane.any()
    assert not log.lanes[log.frames[1]].lane_element.any()
    assert log.lanes[log.frames[0]].lane_element.tolist() == [[1, 0], [0, 1], [0, 0]]


def test_nan_and_text_entries_of_a_topology_read_as_no_link(segment: Path) -> None:
    file = edit(
        segment,
        0,
        lambda d: d["annotation"].update(topology_lclc=[["1", 0, "NAN"], [0, 0, 0.7], [0, 0, 0]]),
    )
    file.write_text(file.read_text().replace('"NAN"', "NaN"))
    log = read_openlane_segment(segment)
    found = problems_of(log)
    # The text "1" and the NaN read as 0; 0.7 in a ground truth is a link (past 0.5).
    assert any("topology_lclc: 2 entries are not finite numbers" in p for p in found), found
    assert any("topology_lclc: 1 entries are not 0 or 1 (read as 1 past 0.5)" in p for p in found)
    assert log.lanes[log.frames[0]].lane_lane.tolist() == [[0, 0, 0], [0, 0, 1], [0, 0, 0]]


def test_nan_in_a_lane_drops_it_and_the_frame_stays(segment: Path) -> None:
    file = info_files(segment)[0]
    document = json.loads(file.read_text())
    document["annotation"]["lane_centerline"][2]["points"][0][0] = math.nan
    file.write_text(json.dumps(document))  # Python writes the NaN literal
    log = read_openlane_segment(segment)
    assert any("lane_centerline[2].points" in p for p in problems_of(log))
    assert log.lanes[log.frames[0]].lane_ids == ("1", "2")


def test_odd_names_other_units_and_big_files_are_reported(segment: Path) -> None:
    info = segment / "info"
    (info / "notes.json").write_text("{}")
    (info / f"{US_START}.json").write_text("{}")  # µs among ns
    big = info_files(segment)[1]
    big.write_text(big.read_text() + " " * (1 << 20))
    log = read_openlane_segment(segment, max_file_mb=1)
    found = problems_of(log)
    assert any("notes.json file name: not <timestamp>.json" in p for p in found), found
    assert any("1 timestamps are not in the segment's unit (ns" in p for p in found)
    assert any(big.name in p and "larger than 1 MB" in p for p in found)
    assert len(log.frames) == FRAMES - 1


def test_a_segment_with_no_usable_file_is_one_line(segment: Path, tmp_path: Path) -> None:
    for file in info_files(segment):
        file.write_text("{")
    with pytest.raises(InputError, match=r"no usable info file \(info/.*invalid JSON"):
        read_openlane_segment(segment)
    empty = tmp_path / "empty" / "info"
    empty.mkdir(parents=True)
    with pytest.raises(InputError, match=r"no <timestamp>.json info files"):
        open_run(empty)


# --- the command line --------------------------------------------------------------------


def test_diagnose_a_segment_on_the_command_line(segment: Path) -> None:
    result = run_script("diagnose", str(segment))
    assert result.returncode == 0, result.stderr
    out = result.stdout
    assert "6 frames judged" in out and "verdict: inconclusive: collision unknown (" in out
    assert "no fault found" not in out
    assert "perception" in out and "not judged (no actors" in out
    assert "input problems: 0" in out


def test_inspect_lists_the_capability_record(segment: Path, tmp_path: Path) -> None:
    folder = write_openlane_predictions(tmp_path / "pred", segment, "perfect")
    result = run_script("inspect", str(segment / "info"), "--predictions", str(folder))
    assert result.returncode == 0, result.stderr
    assert "ego: derived" in result.stdout
    assert "detections_2d: real" in result.stdout
    assert "actors: OpenLane-V2 holds no actors" in result.stdout


def test_a_batch_job_diagnoses_a_segment_and_names_its_format(segment: Path) -> None:
    from ads_rca.batch.work import Job, run_job
    from ads_rca.sources.bag.options import BagOptions

    job = Job("s1", str(segment), make_params("corrected"), 64.0, BagOptions(), 60.0)
    outcome = run_job(job)
    assert outcome.row["format"] == "OpenLane-V2 segment" and not outcome.row.get("error")
    assert outcome.json is not None and len(json.loads(outcome.json)["frames"]) == FRAMES


def test_lane_graphs_survive_a_bag_and_a_log_folder(segment: Path, tmp_path: Path) -> None:
    """The segment → bag (map/lanes, map/lanes_predicted) → log folder (lanes/,
    lanes_predicted/) → the same graphs, exactly."""
    from logcompare import assert_logs_equal

    from ads_rca.sources.bag.reader import read_bag
    from ads_rca.sources.log.reader import read_run_log

    folder = write_openlane_predictions(tmp_path / "pred", segment, "missing_sign")
    bag, out = tmp_path / "bag", tmp_path / "folder"
    converted = run_script("convert", str(segment), str(bag), "--predictions", str(folder))
    assert converted.returncode == 0, converted.stderr
    assert run_script("convert", str(bag), str(out)).returncode == 0
    original = read_openlane_segment(segment, source=SourceOptions(predictions=str(folder)))
    for back in (read_bag(bag), read_run_log(out)):
        only = [
            RunLog.from_folders(log.metadata, (), {"lanes": log.lanes, "lanes_predicted": p})
            for log, p in ((original, original.lanes_predicted), (back, back.lanes_predicted))
        ]
        only[1].metadata = only[0].metadata
        assert_logs_equal(only[0], only[1], check_frames=False)
    document = json.loads(next((out / "lanes").glob("*.json")).read_text())
    assert document["lane_centerline"][1]["points"][0] == [0.0, 3.5, 0.0]  # y left again
    assert "confidence" not in document["lane_centerline"][0]


def test_replay_of_a_segment_equals_diagnose_and_records_its_lanes(
    ros_env: RosEnv, segment: Path, tmp_path: Path
) -> None:
    """Player, monitors, aggregator and recorder over DDS with a model's results: the same
    frames and verdict as diagnose (reference perception judged on the predicted elements),
    and the recording's map/lanes and map/lanes_predicted give the graphs back."""
    from logcompare import assert_logs_equal

    from ads_rca.ros.launcher import ManagedProcess
    from ads_rca.sources.bag.reader import read_bag

    folder = write_openlane_predictions(tmp_path / "pred", segment, "perfect")
    bag, out = tmp_path / "bag", tmp_path / "verdict.json"
    argv = [sys.executable, "-m", "ads_rca.cli", "replay", str(segment), "--json", str(out)]
    argv += ["--predictions", str(folder), "--semantics", "reference", "--record", str(bag)]
    argv += ["--domain-id", str(ros_env.domain_id), "--timeout", "90"]
    replay = ManagedProcess("replay", argv, ros_env.env)
    assert replay.wait(120) == 0, replay.output
    live = json.loads(out.read_text())
    log = read_openlane_segment(segment, source=SourceOptions(predictions=str(folder)))
    offline = diagnose(log, make_params("reference")).to_json()
    for key in ("frames", "modules_judged", "verdict"):
        assert live[key] == offline[key], key
    assert live["modules_judged"]["perception"] == "judged"
    recorded = read_bag(bag)
    for name in ("lanes", "lanes_predicted"):
        expected = RunLog.from_folders(log.metadata, (), {name: log.folder(name)})
        back = RunLog.from_folders(log.metadata, (), {name: recorded.folder(name)})
        assert_logs_equal(expected, back, check_frames=False)
