"""CARLA experiment-client runs: every field mapped as worked out by
hand on the synthesised straight-road scene (test/writers/carla_runs.py), both telemetry
schema versions and the CSV, the capability record, annotations, the run's own figures, the
format choice, hostile files, and the live graph (a real replay over DDS: the same verdict
as diagnose, the annotation on its topic, the modules without data STALE).
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
from writers.carla_runs import write_carla_run

from ads_rca.diagnosis.engine import diagnose
from ads_rca.diagnosis.summary import summary_text
from ads_rca.errors import InputError
from ads_rca.params import make_params
from ads_rca.ros.launcher import ManagedProcess
from ads_rca.sources.carla.annotations import MAX_TEXT, annotations_from_document
from ads_rca.sources.carla.figures import ActorRows, EgoTrack, run_figures, world_velocity
from ads_rca.sources.carla.reader import read_carla_run
from ads_rca.sources.registry import detect_format, open_run

if TYPE_CHECKING:
    from conftest import RosEnv

ADS_RCA = str(Path(sys.executable).with_name("ads-rca"))
MKZ_2020 = (2.446, 0.918, 0.745)  # scenario.yaml's ego_vehicle
MODEL3 = (2.396, 1.082, 0.744)
ADULT = (0.188, 0.188, 0.930)
CAR_DEFAULT = (2.337, 0.966, 0.767)


def problems_of(log: Any) -> list[str]:
    return [f"{p.file} {p.field}: {p.issue} ({p.action})" for p in log.problems]


# --- the model, by hand ----------------------------------------------------------------------


@pytest.mark.parametrize("schema", ["v0", "v0.2"])
def test_every_field_maps_as_worked_out_by_hand(tmp_path: Path, schema: str) -> None:
    log = read_carla_run(write_carla_run(tmp_path / "run", schema))
    assert problems_of(log) == []
    assert log.frame_ms == 50 and log.frames == tuple(range(0, 2000, 50))
    assert log.metadata.collision_frame == -1 and log.metadata.total_frames == 40
    raw = log.metadata.raw
    assert raw["telemetry_schema"] == schema and raw["source_format"] == "carla_experiment_client"
    assert (raw["scenario_id"], raw["map"], raw["seed"]) == ("lane_change_cut_in", "Town05", 7)
    pose = log.pose[350]  # tick 7, t = 0.35 s
    assert (pose.x, pose.y, pose.z, pose.yaw) == (3.5, 0.0, 0.5, 0.0)
    assert pose.speed == 10.0  # v0.2: speed_fd, not speed_actor (0 under teleport)
    actors = log.actors[350]
    # the ego first, at its pose; vehicles and walkers in file order; no light, no sensor
    assert actors.ids == ("ego", "101", "202", "505")
    np.testing.assert_allclose(
        actors.location,
        [[3.5, 0.0, 0.5], [30 + 5 * 0.35, 0.0, 0.5], [20.0, 8 - 2 * 0.35, 0.5], [10, 20, 0.5]],
    )
    assert actors.rotation[2].tolist() == [0.0, 0.0, -90.0]
    np.testing.assert_allclose(actors.extent, [MKZ_2020, MODEL3, ADULT, CAR_DEFAULT])


def test_the_csv_gives_the_ego_alone(tmp_path: Path) -> None:
    log = read_carla_run(write_carla_run(tmp_path / "run", "csv"))
    assert problems_of(log) == []
    assert len(log.frames) == 40 and log.pose[1950].x == pytest.approx(19.5)
    assert all(a.ids == ("ego",) for a in log.actors.values())
    assert log.inputs["actors"].state == "derived"
    assert "no other actor" in log.inputs["actors"].reason
    assert math.isnan(log.metadata.raw["run_figures"]["min_ttc_s"] or math.nan)
    # No actor is recorded: the collision count is unknown, never 0 (issue 39 item 5).
    count = log.metadata.raw["run_figures"]["collision_count"]
    assert count is None or math.isnan(count), count


def test_the_reference_path_is_a_plan_of_the_next_ten_frames(tmp_path: Path) -> None:
    root = write_carla_run(tmp_path / "run", plan_offset_m=0.5)
    plan = read_carla_run(root).waypoints[350]
    assert plan.keys == tuple(str(i) for i in range(11))
    np.testing.assert_allclose(plan.xy, [[10 * (0.35 + 0.05 * i), -0.5] for i in range(11)])
    assert plan.speed.tolist() == [10.0] * 11
    # a path ending at t = 1.0 s: the frame at 0.8 s plans 5 points, the one at 1.05 s none
    document = json.loads((root / "plan.json").read_text())
    trajectory = document["actors"][0]["trajectory"]
    document["actors"][0]["trajectory"] = [p for p in trajectory if p["t"] <= 1.0 + 1e-9]
    (root / "plan.json").write_text(json.dumps(document))
    plans = read_carla_run(root).waypoints
    assert len(plans[800]) == 5 and 1050 not in plans


def test_the_capability_record_says_what_is_real_assumed_derived_and_absent(
    tmp_path: Path,
) -> None:
    log = read_carla_run(write_carla_run(tmp_path / "run"))
    states = {name: status.state for name, status in log.inputs.items()}
    assert states == {
        "ego": "real",
        "actors": "assumed",
        "detections_2d": "absent",
        "ground_truth_2d": "absent",
        "detections_3d": "absent",
        "tracked_objects": "absent",
        "predictions": "absent",
        "predictions_gt": "absent",
        "plan": "derived",
        "control": "absent",
        "collision": "absent",
        "clock": "absent",
    }
    reason = log.inputs["actors"].reason
    assert "vehicle.custom.prototype" in reason  # the blueprint the table lacks
    assert "traffic_light (40)" in reason and "unknown (40)" in reason
    assert "vehicle.lincoln.mkz_2020" in reason
    assert log.metadata.raw["model_inputs"]["plan"]["state"] == "derived"


# --- the run's own figures ---------------------------------------------------------------------


def test_body_frame_velocities_turn_into_the_world_frame() -> None:
    """vx forward, vy LEFT (SAE) into CARLA's left-handed world (y right, yaw clockwise)."""
    ego = EgoTrack(
        np.zeros((3, 2)),
        np.array([90.0, 0.0, 0.0]),
        np.array([10.0, 0.0, 3.0]),
        np.array([[10.0, 0.0], [0.0, 1.0], [math.nan, math.nan]]),
        np.array([2.0, 1.0]),
    )
    np.testing.assert_allclose(world_velocity(ego), [[0, 10], [0, -1], [3, 0]], atol=1e-12)


def test_brakes_jerk_and_ttc_as_worked_out_by_hand() -> None:
    """20 ticks at 20 fps: 10 m/s, then 0.5 m/s slower each tick for 5 ticks (−10 m/s²)."""
    speed = np.array([10.0] * 10 + [9.5, 9.0, 8.5, 8.0, 7.5] + [7.5] * 5)
    ego = EgoTrack(
        np.c_[np.arange(20.0), np.zeros(20)],
        np.zeros(20),
        speed,
        np.c_[speed, np.zeros(20)],
        np.array([2.0, 1.0]),
    )
    # one vehicle 10 m ahead of tick 0 at 5 m/s, one walker nearer (not a lead vehicle)
    rows = ActorRows(
        np.array([0, 0]),
        np.array([0, 1]),
        np.array([[10.0, 0.0], [5.0, 0.0]]),
        np.zeros(2),
        np.array([[2.0, 1.0], [0.2, 0.2]]),
        np.array([5.0, 0.0]),
        np.array([True, False]),
    )
    figures = run_figures(ego, rows, 0.05)
    assert figures["hard_brake_count"] == 5
    assert figures["accel_rms_longitudinal"] == pytest.approx(math.sqrt(100 * 5 / 20))
    assert figures["jerk_rms_longitudinal"] == pytest.approx(math.sqrt(2 * 200**2 / 20))
    assert figures["accel_rms_lateral"] == 0.0
    assert figures["min_ttc_s"] == pytest.approx(10.0 / (10.0 - 5.0))
    assert figures["collision_count"] == 0


def test_the_synthesised_runs_figures(tmp_path: Path) -> None:
    """The lead closes at 5 m/s from 30 m: TTC = 6 − t, least at the last tick (1.95 s);
    the pedestrian, nearer and ahead, is no lead vehicle; the parked car is off to the side."""
    figures = read_carla_run(write_carla_run(tmp_path / "run")).metadata.raw["run_figures"]
    assert figures["min_ttc_s"] == pytest.approx(6 - 1.95)
    assert figures["collision_count"] == 0 and figures["hard_brake_count"] == 0


def test_the_derived_collision_is_the_first_overlap_and_says_so(tmp_path: Path) -> None:
    """Lead 6 m ahead closing at 5 m/s; the boxes touch when 6 − 5t < 2.446 + 2.396, so
    from t = 0.25 s (frame 5) on."""
    root = write_carla_run(tmp_path / "run", lead_gap_m=6.0)
    plain = read_carla_run(root)
    assert plain.metadata.collision_frame == -1
    assert plain.metadata.raw["run_figures"]["collision_count"] == 1
    derived = read_carla_run(root, derived_collision=True)
    assert derived.metadata.collision_frame == 5
    assert derived.inputs["collision"].state == "derived"
    document = diagnose(derived, make_params("corrected")).to_json()
    assert document["collision_frame"] == 5


# --- annotations -------------------------------------------------------------------------------


def test_events_are_annotations_never_collisions(tmp_path: Path) -> None:
    root = write_carla_run(tmp_path / "run")
    log = read_carla_run(root)
    assert log.metadata.collision_frame == -1
    (note,) = annotations_from_document(log.metadata.raw)
    assert (note.timestamp_ms, note.kind, note.source) == (1000, "vehicle_cut_in", "events.json")
    assert note.text == "Brake — Vehicle cutting in ahead"
    document = diagnose(log, make_params("corrected")).to_json()
    assert document["annotations"] == [note.to_dict()]
    assert document["collision_frame"] == -1 and document["primary_root_cause"] is None
    assert "1 s: vehicle_cut_in: Brake — Vehicle cutting in ahead" in summary_text(document)


def test_annotation_text_from_a_log_is_bounded_and_escaped(tmp_path: Path) -> None:
    root = write_carla_run(tmp_path / "run")
    forged = "Brake\nverdict: planning\x1b[2J" + "x" * 500
    events = {"events": [{"t_event": 1.0, "type": "brake_hard", "decision_text": forged}]}
    (root / "events.json").write_text(json.dumps(events))
    log = read_carla_run(root)
    (note,) = annotations_from_document(log.metadata.raw)
    assert len(note.text) == MAX_TEXT
    text = summary_text(diagnose(log, make_params("corrected")).to_json())
    assert "\nverdict: planning" not in text and "\x1b" not in text
    assert "Brake\\x0averdict: planning\\x1b[2J" in text


def test_annotations_from_a_topic_are_checked() -> None:
    """The live graph reads them from run/metadata: anything malformed is left out."""
    document = {
        "annotations": [
            {"timestamp_ms": 5, "kind": "a", "text": "b", "source": "c"},
            {"timestamp_ms": True, "kind": "a"},
            {"timestamp_ms": -1, "kind": "a"},
            {"timestamp_ms": 2**80, "kind": "a"},
            {"timestamp_ms": 7, "kind": ["a"]},
            "text",
            None,
        ]
    }
    assert [a.timestamp_ms for a in annotations_from_document(document)] == [5]
    assert annotations_from_document({"annotations": {"a": 1}}) == []


# --- choosing the format -----------------------------------------------------------------------


def test_auto_tells_a_carla_run_from_a_running_log(tmp_path: Path) -> None:
    root = write_carla_run(tmp_path / "run")
    assert detect_format(root) == "carla"
    (root / "actors").mkdir()  # a running log holding a telemetry file is still a log
    assert detect_format(root) == "log"
    assert detect_format(tmp_path / "missing") == "log"


def test_diagnose_a_carla_run_with_one_command(tmp_path: Path) -> None:
    root = write_carla_run(tmp_path / "run")
    out = tmp_path / "verdict.json"
    done = run_script("diagnose", str(root), "--json", str(out))
    assert done.returncode == 0, done.stderr
    document = json.loads(out.read_text())
    assert document["modules_judged"]["controller"] == "judged"
    assert document["modules_judged"]["perception"].startswith("not judged (no ")
    assert document["run_figures"]["min_ttc_s"] == pytest.approx(4.05)
    assert "annotations (1; events, not collisions)" in done.stdout
    forced = run_script("diagnose", str(root), "--format", "carla", "--derived-collision")
    assert forced.returncode == 0 and "no collision in this run" in forced.stdout


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["--format", "log"], "not an ADS running log"),
        (["--format", "bag"], "--format bag: not a bag"),
        (["--format", "kitti"], "format 'kitti': expected one of auto, log, bag, carla"),
        (["-p", "format=" + "x" * 80], "expected one of auto"),
        (["-p", "derived_collision=maybe"], "derived_collision: expected true or false"),
        (["--profile", "carla-autoware"], "apply to bags, not to a CARLA run folder"),
    ],
)
def test_a_wrong_format_choice_is_one_line(tmp_path: Path, argv: list[str], expected: str) -> None:
    root = write_carla_run(tmp_path / "run")
    done = run_script("diagnose", str(root), *argv)
    assert done.returncode == 2, done.stdout
    assert expected in done.stderr and "Traceback" not in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1


def test_carla_options_on_other_inputs_are_one_line(
    tmp_path: Path, log_dirs: Callable[[str, str], Path]
) -> None:
    log_dir = log_dirs("cut_in", "planning")
    for argv, expected in (
        (["--derived-collision"], "derived collision check applies to CARLA runs and DLP scenes"),
        (["--format", "carla"], "no telemetry.json or telemetry.csv"),
    ):
        done = run_script("diagnose", str(log_dir), *argv)
        assert done.returncode == 2 and expected in done.stderr, done.stderr
        assert len(done.stderr.strip().splitlines()) == 1


# --- hostile files -----------------------------------------------------------------------------


def _telemetry(root: Path) -> dict[str, Any]:
    document: dict[str, Any] = json.loads((root / "telemetry.json").read_text())
    return document


def _edit_telemetry(root: Path, edit: Callable[[dict[str, Any]], None]) -> None:
    document = _telemetry(root)
    edit(document)
    (root / "telemetry.json").write_text(json.dumps(document))


def _set(path: str, value: Any, tick: int = 3) -> Callable[[dict[str, Any]], None]:
    def edit(document: dict[str, Any]) -> None:
        node: Any = document["frames"][tick]
        *parents, last = path.split(".")
        for key in parents:
            node = node[int(key)] if key.isdigit() else node[key]
        node[int(last) if last.isdigit() else last] = value

    return edit


HOSTILE_TELEMETRY: dict[str, tuple[Callable[[dict[str, Any]], None], str, int]] = {
    # case: (edit, the problem's field and issue, analysed frames left)
    "text for a number": (
        _set("ego.position.x", "0.15"),
        "frames[3].ego.position.x: '0.15' is text, not a number (value kept)",
        40,
    ),
    "a word for a number": (
        _set("ego.position.y", "north"),
        "frames[3].ego.position.y: 'north' is not a number (read as NaN)",
        40,
    ),
    "no position": (_set("ego.position", None), "frames[3].ego.position: missing", 39),
    "no ego": (_set("ego", []), "frames[3].ego: expected an object, found a list", 39),
    "time repeated": (_set("t_sim", 0.1), "t_sim: time repeated (frame skipped)", 39),
    "negative time": (_set("t_sim", -1.0), "frames[3].t_sim: -1.0 s is outside the log's", 39),
    "no time at all": (
        lambda d: d["frames"].__setitem__(3, {"ego": d["frames"][3]["ego"]}),
        "frames[3].t_sim: missing (no frame either)",
        39,
    ),
    "actor named ego": (
        _set("actors.0.id", "ego"),
        "frames[3].actors[0].id: 'ego' is the ego's actor id (record dropped)",
        40,
    ),
    "actor listed twice": (
        _set("actors.1.id", 101),
        "frames[3].actors[1].id: 101 is listed twice in this tick (record dropped)",
        40,
    ),
    "actor id an object": (
        _set("actors.0.id", {"a": 1}),
        "frames[3].actors[0].id: {'a': 1} is not an id (record dropped)",
        40,
    ),
    "actors not a list": (
        _set("actors", "everyone"),
        "frames[3].actors: expected a list, found text (ignored)",
        40,
    ),
    "frames out of order": (
        lambda d: d["frames"].reverse(),
        "t_sim: ticks not in time order (sorted)",
        40,
    ),
    "a tick that is not an object": (
        lambda d: d["frames"].__setitem__(5, 7),
        "frames[5]: expected an object, found int (frame skipped)",
        39,
    ),
}


@pytest.mark.parametrize("case", sorted(HOSTILE_TELEMETRY))
def test_a_bad_tick_or_value_is_reported_and_the_rest_diagnosed(tmp_path: Path, case: str) -> None:
    edit, expected, frames = HOSTILE_TELEMETRY[case]
    root = write_carla_run(tmp_path / "run")
    _edit_telemetry(root, edit)
    log = read_carla_run(root)
    found = problems_of(log)
    assert any(expected in line and line.startswith("telemetry.json") for line in found), found
    assert len(log.frames) == frames
    document = diagnose(log, make_params("corrected")).to_json()
    assert document["modules_judged"]["controller"] == "judged"
    json.dumps(document, allow_nan=False)  # the contract stays strict JSON


@pytest.mark.parametrize(
    ("file", "content", "expected"),
    [
        ("run_metadata.json", b'{"fps": "fast"}', "run_metadata.json fps: 'fast' is not a number"),
        ("run_metadata.json", b'{"fps": 0}', "run_metadata.json fps: 0.0 is not a frame rate"),
        ("run_metadata.json", b"[1, 2", "run_metadata.json : invalid JSON"),
        ("events.json", b'{"events": [{"t_event": NaN}]}', "events[0].t_event: not a time"),
        ("events.json", b'{"events": [{"t": 1, "type": 5}]}', "events[0]: type, decision_text"),
        ("events.json", b'{"events": 3}', "events.json events: expected an object"),
        ("plan.json", b'{"actors": []}', "plan.json actors: no actor with role ego"),
        ("plan.json", b'{"actors": [{"role": "ego", "trajectory": [{"t": 0}]}]}', "points"),
        ("scenario.yaml", b"a: &a [*a]\nego_vehicle: [1", "scenario.yaml"),
        ("scenario.yaml", b"ego_vehicle: 5\n", "scenario.yaml ego_vehicle: not text"),
    ],
)
def test_a_bad_side_file_is_reported_and_its_default_used(
    tmp_path: Path, file: str, content: bytes, expected: str
) -> None:
    root = write_carla_run(tmp_path / "run")
    (root / file).write_bytes(content)
    log = read_carla_run(root)
    found = problems_of(log)
    assert any(expected in line for line in found), found
    assert len(log.frames) == 40
    diagnose(log, make_params("reference"))


def test_a_truncated_json_falls_back_to_the_csv_and_says_so(tmp_path: Path) -> None:
    root = write_carla_run(tmp_path / "run")
    csv_run = write_carla_run(tmp_path / "csv", "csv")
    (root / "telemetry.csv").write_bytes((csv_run / "telemetry.csv").read_bytes())
    data = (root / "telemetry.json").read_bytes()
    (root / "telemetry.json").write_bytes(data[: len(data) // 2])
    log = read_carla_run(root)
    assert len(log.frames) == 40 and log.metadata.raw["telemetry_schema"] == "csv"
    found = problems_of(log)
    assert any(line.startswith("telemetry.json : invalid JSON") for line in found), found
    assert any("telemetry.csv read instead" in line for line in found), found


@pytest.mark.parametrize(
    ("damage", "expected"),
    [
        ("truncated", "no usable tick in its telemetry (telemetry.json: file: invalid JSON"),
        ("no frames", "no usable tick in its telemetry (telemetry.json: frames: expected a list"),
        ("fifo", "no usable tick in its telemetry (telemetry.json: file: not a regular file"),
        ("missing", "no telemetry.json or telemetry.csv"),
        ("csv binary", "no usable tick in its telemetry (telemetry.csv: file: unreadable CSV"),
        ("csv header", "no usable tick in its telemetry (telemetry.csv: header: no column"),
    ],
)
def test_a_run_without_usable_telemetry_is_one_line(
    tmp_path: Path, damage: str, expected: str
) -> None:
    root = write_carla_run(tmp_path / "run", "csv" if damage.startswith("csv") else "v0")
    telemetry = root / "telemetry.json"
    if damage == "truncated":
        telemetry.write_bytes(telemetry.read_bytes()[:100])
    elif damage == "no frames":
        telemetry.write_text('{"frames": {}}')
    elif damage == "fifo":
        telemetry.unlink()
        os.mkfifo(telemetry)
    elif damage == "missing":
        telemetry.unlink()
    elif damage == "csv binary":
        (root / "telemetry.csv").write_bytes(b"frame,t_sim\n\xff\xfe\x00,\x81\n")
    elif damage == "csv header":
        (root / "telemetry.csv").write_text("frame,t_sim,speed\n0,0,1\n")
    with pytest.raises(InputError) as error:
        read_carla_run(root)
    assert expected in str(error.value), str(error.value)
    done = run_script("diagnose", str(root), "--format", "carla")
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr


def test_a_huge_telemetry_file_is_refused_by_max_file_mb(tmp_path: Path) -> None:
    root = write_carla_run(tmp_path / "run")
    with pytest.raises(InputError, match="larger than"):
        open_run(root, max_file_mb=0.001)


# --- the live graph ----------------------------------------------------------------------------


def test_replay_of_a_carla_run_equals_diagnose_with_its_annotation_and_no_data(
    ros_env: RosEnv, tmp_path: Path
) -> None:
    """Player, monitors, aggregator and recorder in their own processes over DDS: the same
    verdict as diagnose (frames, modules judged, annotations, figures); the annotation on
    run/annotations; each module the run has no data for STALE on /diagnostics, never OK."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    root = write_carla_run(tmp_path / "run", "v0.2")
    bag, out = tmp_path / "bag", tmp_path / "verdict.json"
    argv = [sys.executable, "-m", "ads_rca.cli", "replay", str(root), "--record", str(bag)]
    argv += ["--json", str(out), "--domain-id", str(ros_env.domain_id), "--timeout", "90"]
    replay = ManagedProcess("replay", argv, ros_env.env)
    assert replay.wait(120) == 0, replay.output
    live = json.loads(out.read_text())
    offline = diagnose(read_carla_run(root), make_params("corrected")).to_json()
    for key in ("frames", "modules_judged", "annotations", "run_figures", "verdict"):
        assert live[key] == offline[key], key
    notes: list[dict[str, Any]] = []
    levels: dict[str, set[int]] = {}
    with next(bag.glob("*.mcap")).open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _schema, channel, _raw, msg in reader.iter_decoded_messages(log_time_order=False):
            if channel.topic.endswith("/run/annotations"):
                notes.append(json.loads(msg.data))
            elif channel.topic == "/diagnostics":
                for status in msg.status:
                    levels.setdefault(status.name, set()).add(int(status.level))
    assert [(n["timestamp_ms"], n["kind"]) for n in notes] == [(1000, "vehicle_cut_in")]
    perception = next(name for name in levels if name.endswith("perception"))
    assert levels[perception] == {3}, levels  # STALE: no data, never OK
    controller = next(name for name in levels if name.endswith("controller"))
    assert 0 in levels[controller]


def test_a_batch_job_diagnoses_a_carla_run_and_names_its_format(tmp_path: Path) -> None:
    from ads_rca.batch.work import Job, run_job
    from ads_rca.sources.bag.options import BagOptions
    from ads_rca.sources.formats import SourceOptions

    root = write_carla_run(tmp_path / "run", lead_gap_m=6.0)
    params = make_params("corrected")
    job = Job(
        "r1", str(root), params, 64.0, BagOptions(), 60.0, SourceOptions(derived_collision=True)
    )
    outcome = run_job(job)
    assert outcome.row["format"] == "CARLA run" and not outcome.row.get("error"), outcome.row
    assert outcome.row["collision_frame"] == 5  # derived, as asked
    assert outcome.json is not None and json.loads(outcome.json)["annotations"]


def test_a_frame_rate_that_disagrees_with_the_ticks_is_said(tmp_path: Path) -> None:
    root = write_carla_run(tmp_path / "run")
    facts = json.loads((root / "run_metadata.json").read_text())
    facts["fps"] = 10
    (root / "run_metadata.json").write_text(json.dumps(facts))
    log = read_carla_run(root)
    assert log.frame_ms == 100
    expected = "telemetry.json t_sim: ticks are 50 ms apart, the frame rate gives 100 ms"
    assert any(line.startswith(expected) for line in problems_of(log)), problems_of(log)


def test_convert_writes_a_run_as_a_bag_that_diagnoses_the_same(tmp_path: Path) -> None:
    root = write_carla_run(tmp_path / "run")
    bag, direct, again = tmp_path / "bag", tmp_path / "direct.json", tmp_path / "again.json"
    assert run_script("convert", str(root), str(bag)).returncode == 0
    assert run_script("diagnose", str(root), "--json", str(direct)).returncode == 0
    assert run_script("diagnose", str(bag), "--json", str(again)).returncode == 0
    first, second = json.loads(direct.read_text()), json.loads(again.read_text())
    for key in ("frames", "modules_judged", "verdict", "annotations", "run_figures"):
        assert first[key] == second[key], key
