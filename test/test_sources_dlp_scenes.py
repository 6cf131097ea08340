"""Dragon Lake Parking scenes: every field of the synthesised scene
(test/writers/dlp_scenes.py) as worked out by hand, mirrored headings, the reversing car's
signed speed, the ego's choice, timestamps along the linked list, the capability record,
streaming, hostile files (a broken or looping list, missing and cut files, bad instances),
and a real replay over DDS equal to diagnose.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import dlp_predictor
import numpy as np
import pytest
from commandline import run_script
from writers.dlp_scenes import STEM, frame_token, scene_agents, write_dlp_scene
from writers.predictor_files import write_predictions

from ads_rca.diagnosis.engine import diagnose
from ads_rca.errors import InputError
from ads_rca.params import make_params
from ads_rca.ros.launcher import ManagedProcess
from ads_rca.sources.dlp.reader import read_dlp_scene
from ads_rca.sources.formats import SourceOptions
from ads_rca.sources.registry import detect_format, open_run

if TYPE_CHECKING:
    from conftest import RosEnv

ADS_RCA = str(Path(sys.executable).with_name("ads-rca"))
FRAMES = 50


def ids() -> dict[int, str]:
    """Each synthesised agent's number → its actor id (token order, from 1)."""
    agents = scene_agents(FRAMES)
    ordered = sorted(agents, key=lambda a: a.token)
    return {a.number: str(ordered.index(a) + 1) for a in agents}


def problems_of(log: Any) -> list[str]:
    return [f"{p.file} {p.field}: {p.issue} ({p.action})" for p in log.problems]


@pytest.fixture
def scene(tmp_path: Path) -> Path:
    return write_dlp_scene(tmp_path / "scene", FRAMES)


def test_every_field_maps_as_worked_out_by_hand(scene: Path) -> None:
    log = read_dlp_scene(scene)
    assert problems_of(log) == []
    assert log.frame_ms == 40 and log.frames == tuple(range(0, 40 * FRAMES, 40))
    assert log.metadata.collision_frame == -1
    number = ids()
    ego = log.metadata.raw["ego_agent"]
    assert (ego["id"], ego["type"], ego["frames"]) == (number[1], "Car", FRAMES)
    assert ego["chosen_by"] == "default: the longest-lived moving car"
    pose = log.pose[400]  # frame 10, t = 0.4 s: car 1 at (10 + 5 * 0.4, 20) in DLP's frame
    assert (pose.x, pose.y, pose.z, pose.yaw, pose.speed) == (12.0, -20.0, 0.0, 0.0, 5.0)
    actors = log.actors[400]
    obstacle = "4"  # after the three agents
    assert actors.ids == (number[1], *sorted((number[2], number[3]), key=int), obstacle)
    row = {actor_id: n for n, actor_id in enumerate(actors.ids)}
    expected = {
        number[1]: ([12.0, -20.0, 0.0], 0.0, [2.35, 0.95, 0.75]),
        number[2]: ([40 - 2.5 * 0.2, -30.0, 0.0], 0.0, [2.25, 0.9, 0.75]),  # reversing
        number[3]: ([25.0, -(10 + 0.4), 0.0], -90.0, [0.415, 0.415, 0.9]),  # mirrored π/2
        obstacle: ([60.0, -5.0, 0.0], -180.0, [2.3, 1.0, 0.75]),
    }
    for actor_id, (location, yaw, extent) in expected.items():
        np.testing.assert_allclose(actors.location[row[actor_id]], location)
        assert actors.rotation[row[actor_id]].tolist() == [0.0, 0.0, yaw]
        np.testing.assert_allclose(actors.extent[row[actor_id]], extent)
    tokens = log.metadata.raw["actor_tokens"]
    assert tokens[number[1]] == scene_agents(FRAMES)[0].token


def test_the_reversing_car_as_ego_has_a_negative_speed(scene: Path) -> None:
    number = ids()
    log = read_dlp_scene(scene, source=SourceOptions(ego_agent=number[2]))
    assert log.frames == tuple(range(5 * 40, (FRAMES - 5) * 40, 40))  # its lifetime
    poses = [log.pose[ts] for ts in log.frames]
    assert {p.speed for p in poses} == {-2.5} and {p.yaw for p in poses} == {0.0}
    assert log.inputs["ego"].state == "real" and "chosen by ego_agent" in log.inputs["ego"].reason


def test_the_speed_sign_follows_the_dlp_api_however_small_the_motion(tmp_path: Path) -> None:
    """Issue 39 item 6: the API (``Dataset.states_from_utm``) negates the speed wherever
    the heading points against the motion from the previous to the next instance, even a
    4 mm jitter of a car standing still; exactly no motion keeps the sign. Car 1 stands
    at (10, 20) heading east, its position at frame 11 measured 4 mm west."""
    path = write_dlp_scene(tmp_path / "scene", FRAMES)
    instances_file = path.parent / f"{STEM}_instances.json"
    instances = json.loads(instances_file.read_text())
    car = scene_agents(FRAMES)[0]
    for frame in range(car.first, car.last + 1):
        instance = instances[car.instance(frame)]
        instance["coords"] = [9.996 if frame == 11 else 10.0, 20.0]
        instance["speed"] = 0.02
    instances_file.write_text(json.dumps(instances))
    log = read_dlp_scene(path, source=SourceOptions(ego_agent=ids()[1]))
    speeds = {log.frames.index(ts): log.pose[ts].speed for ts in log.frames}
    assert speeds[10] == -0.02  # next (frame 11) - previous (frame 9) points west
    assert speeds[12] == 0.02  # frame 13 - frame 11 points east
    assert speeds[11] == 0.02  # frames 10 and 12 stand at one place: no motion
    assert {speeds[f] for f in speeds if f not in (10, 11, 12)} == {0.02}


def test_the_ego_by_token_and_its_mirrored_heading(scene: Path) -> None:
    walker = scene_agents(FRAMES)[2]
    log = read_dlp_scene(scene, source=SourceOptions(ego_agent=walker.token))
    first = log.pose[log.frames[0]]
    assert (first.x, first.y, first.yaw, first.speed) == (25.0, -10.0, -90.0, 1.0)


def test_the_capability_record(scene: Path) -> None:
    log = read_dlp_scene(scene)
    states = {name: status.state for name, status in log.inputs.items()}
    assert states["ego"] == "assumed" and "DLP has no ego" in log.inputs["ego"].reason
    assert states["actors"] == "real"
    assert states["collision"] == "absent"
    absent = [n for n, s in states.items() if s == "absent"]
    assert set(absent) == set(states) - {"ego", "actors"}
    document = diagnose(log, make_params("corrected")).to_json()
    assert all(v.startswith("not judged") for v in document["modules_judged"].values())
    # A DLP scene records no collision: unknown, never "no collision" (docs/verdicts.md).
    assert document["verdict"].startswith(
        "inconclusive: collision unknown (naturalistic data: no collision recorded)"
    )
    assert document["collision"] == "unknown" and document["conclusive"] is False


def test_auto_detects_a_scene_file_and_its_folder(scene: Path) -> None:
    assert detect_format(scene) == detect_format(scene.parent) == "dlp"
    write_dlp_scene(scene.parent / "two", 5)
    (scene.parent / "two" / f"{STEM}_scene.json").rename(scene.parent / "DJI_0002_scene.json")
    with pytest.raises(InputError, match="2 DLP scenes"):
        open_run(scene.parent)


def test_the_derived_collision_is_the_first_overlap(scene: Path) -> None:
    """A parked car moved to (20, 20): car 1 (half length 2.35) reaches it (half length
    2.3) when 10 + 5t > 20 - 4.65, from frame 27 (t = 1.08 s)."""
    obstacles_file = scene.with_name(f"{STEM}_obstacles.json")
    obstacles = json.loads(obstacles_file.read_text())
    for entry in obstacles.values():
        entry["coords"], entry["heading"] = [20.0, 20.0], 0.0
    obstacles_file.write_text(json.dumps(obstacles))
    assert read_dlp_scene(scene).metadata.collision_frame == -1
    log = read_dlp_scene(scene, source=SourceOptions(derived_collision=True))
    assert log.metadata.collision_frame == 27
    assert log.inputs["collision"].state == "derived"


def test_the_instances_are_streamed_not_read_whole(scene: Path) -> None:
    """max_file_mb caps what is read whole; the instances file, far larger, is streamed
    (only each instance is held to the cap)."""
    instances = scene.with_name(f"{STEM}_instances.json")
    assert instances.stat().st_size > 40_000
    log = read_dlp_scene(scene, max_file_mb=0.01)
    assert len(log.frames) == FRAMES and problems_of(log) == []


# --- hostile files -----------------------------------------------------------------------------


def _edit(path: Path, edit: Any) -> None:
    document = json.loads(path.read_text())
    edit(document)
    path.write_text(json.dumps(document))


def test_a_broken_link_ends_the_list_and_says_so(scene: Path) -> None:
    frames_file = scene.with_name(f"{STEM}_frames.json")
    _edit(frames_file, lambda d: d[frame_token(20)].update(next="0" * 40))
    log = read_dlp_scene(scene)
    assert len(log.frames) == 21
    found = problems_of(log)
    assert any("a next link names no frame (the list ends here)" in p for p in found), found
    assert any("29 frames are not on the list from first_frame" in p for p in found), found
    assert any("instances: no frame on the list (record dropped)" in p for p in found), found


def test_a_cycle_ends_the_list_and_says_so(scene: Path) -> None:
    frames_file = scene.with_name(f"{STEM}_frames.json")
    _edit(frames_file, lambda d: d[frame_token(20)].update(next=frame_token(10)))
    log = read_dlp_scene(scene)
    assert len(log.frames) == 21
    assert any("the next links make a cycle" in p for p in problems_of(log))


def test_bad_instances_are_counted_and_dropped(scene: Path) -> None:
    instances_file = scene.with_name(f"{STEM}_instances.json")
    car = scene_agents(FRAMES)[0]

    def damage(document: dict[str, Any]) -> None:
        document[car.instance(3)]["coords"] = ["12", 20]
        document[car.instance(4)]["heading"] = float("nan")
        document[car.instance(5)]["agent_token"] = "nobody"
        document[car.instance(6)] = [1, 2]

    _edit(instances_file, damage)
    log = read_dlp_scene(scene)
    found = problems_of(log)
    for expected in (
        "coords, heading: 2 instances: not finite numbers (record dropped)",
        "agent_token: 1 instances: no agent of the agents file (record dropped)",
        ": 1 instances: not an object (record dropped)",
    ):
        assert any(expected in p for p in found), (expected, found)
    assert len(log.frames) == FRAMES - 4  # the ego's frames without its instance
    assert any("no instance in 4 frames of its lifetime" in p for p in found), found


def test_a_cut_instances_file_keeps_what_came_before(scene: Path) -> None:
    instances_file = scene.with_name(f"{STEM}_instances.json")
    data = instances_file.read_bytes()
    instances_file.write_bytes(data[: len(data) // 3])
    log = read_dlp_scene(scene)
    found = problems_of(log)
    assert any("invalid JSON" in p and "kept" in p for p in found), found
    assert 0 < len(log.frames) < FRAMES


@pytest.mark.parametrize(
    ("damage", "expected"),
    [
        ("no instances", "_instances.json: missing (a DLP scene needs all five files)"),
        ("no agents", "not a usable DLP agents file (missing)"),
        ("scene not an object", "not a usable DLP scene file"),
        ("first frame unknown", "_frames.json: no frame is the scene's first_frame"),
        ("instances fifo", "_instances.json: not a regular file"),
        ("bad ego", "ego_agent 99: no such agent"),
    ],
)
def test_an_unusable_scene_is_one_line(scene: Path, damage: str, expected: str) -> None:
    import os

    part = {name: scene.with_name(f"{STEM}_{name}.json") for name in ("instances", "agents")}
    argv: list[str] = []
    if damage == "no instances":
        part["instances"].unlink()
    elif damage == "no agents":
        part["agents"].unlink()
    elif damage == "scene not an object":
        scene.write_text("[]")
    elif damage == "first frame unknown":
        _edit(scene, lambda d: d.update(first_frame="x"))
    elif damage == "instances fifo":
        part["instances"].unlink()
        os.mkfifo(part["instances"])
    elif damage == "bad ego":
        argv = ["--ego-agent", "99"]
    done = run_script("diagnose", str(scene), *argv)
    assert done.returncode == 2, done.stdout
    assert expected in done.stderr and "Traceback" not in done.stderr, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr


def test_no_usable_instance_names_the_file_and_the_cause(scene: Path) -> None:
    """Every agent's instances unusable (NaN coords, tokens of no agent): one line naming
    the instances file and why, counted (issue 43, item 6b: it said neither)."""
    instances_file = scene.with_name(f"{STEM}_instances.json")

    def damage(document: dict[str, Any]) -> None:
        for n, entry in enumerate(document.values()):
            if n % 2:
                entry["coords"] = [float("nan"), 0]
            else:
                entry["agent_token"] = "nobody"

    _edit(instances_file, damage)
    total = len(json.loads(instances_file.read_text()))
    done = run_script("diagnose", str(scene))
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert f"{instances_file}: no agent has a usable instance in the scene" in done.stderr
    assert f"0 of its {total} instances usable" in done.stderr
    assert f"agent_token: {total - total // 2} instances: no agent of the agents file" in (
        done.stderr
    )
    assert f"coords, heading: {total // 2} instances: not finite numbers" in done.stderr


def test_an_ego_agent_without_a_usable_instance_names_the_file_and_the_cause(
    scene: Path,
) -> None:
    instances_file = scene.with_name(f"{STEM}_instances.json")
    car = scene_agents(FRAMES)[0]
    _edit(
        instances_file,
        lambda d: [d[car.instance(f)].update(heading=None) for f in range(FRAMES)],
    )
    with pytest.raises(InputError) as error:
        read_dlp_scene(scene, source=SourceOptions(ego_agent=car.token))
    message = str(error.value)
    assert message.startswith(
        f"{instances_file}: ego_agent {car.token}: agent {car.token} has no usable instance ("
    )
    assert f"coords, heading: {FRAMES} instances: not finite numbers" in message


def test_ego_agent_elsewhere_is_one_line(tmp_path: Path) -> None:
    from writers.carla_runs import write_carla_run

    done = run_script("diagnose", str(write_carla_run(tmp_path / "run")), "--ego-agent", "1")
    assert done.returncode == 2 and "ego_agent applies to DLP scenes" in done.stderr
    long = run_script("diagnose", str(tmp_path / "run"), "--ego-agent", "x" * 100)
    assert long.returncode == 2 and "ego_agent: expected an agent token" in long.stderr


# --- the live graph ----------------------------------------------------------------------------


def test_replay_of_a_dlp_scene_equals_diagnose(
    ros_env: RosEnv, scene: Path, tmp_path: Path
) -> None:
    """Player, monitors, aggregator and recorder over DDS, the reversing car as the ego and
    a predictor's files: the same frames, verdict and prediction scores as diagnose; on
    /diagnostics the prediction module is OK where it scored, perception STALE (no data)."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    ego = ids()[2]
    log = read_dlp_scene(scene, source=SourceOptions(ego_agent=ego))
    predictions = write_predictions(log, tmp_path / "pred", bias=(0.0, 1.0), ego_id=ego)
    bag, out = tmp_path / "bag", tmp_path / "verdict.json"
    argv = [sys.executable, "-m", "ads_rca.cli", "replay", str(scene), "--json", str(out)]
    argv += ["--ego-agent", ego, "--predictions", str(predictions), "--record", str(bag)]
    argv += ["--domain-id", str(ros_env.domain_id), "--timeout", "90"]
    # Paced (4 s): a monitor says one status per batch it judged, for the batch's latest
    # frame; unpaced on a loaded machine one batch can hold the run and its status is then
    # the last frame's (STALE: no future to score), hiding the frames that scored.
    argv += ["--rate", "0.5"]
    replay = ManagedProcess("replay", argv, ros_env.env)
    assert replay.wait(120) == 0, replay.output
    live = json.loads(out.read_text())
    source = SourceOptions(ego_agent=ego, predictions=str(predictions))
    offline = diagnose(open_run(scene, source=source), make_params("corrected")).to_json()
    for key in ("frames", "modules_judged", "verdict", "ego_id", "prediction_scores"):
        assert live[key] == offline[key], key
    assert len(live["frames"]) == FRAMES - 10
    assert live["prediction_scores"]["ade"] == pytest.approx(1.0)
    levels: dict[str, set[int]] = {}
    with next(bag.glob("*.mcap")).open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _schema, channel, _raw, msg in reader.iter_decoded_messages(log_time_order=False):
            if channel.topic == "/diagnostics":
                for status in msg.status:
                    levels.setdefault(status.name, set()).add(int(status.level))
    by_module = {
        m: next(v for k, v in levels.items() if k.endswith(m)) for m in ("perception", "prediction")
    }
    assert by_module["perception"] == {3}, levels  # STALE: no data
    assert 0 in by_module["prediction"], levels  # OK where it scored (STALE at the end,
    # where the predictor has no future to give)


# --- prediction scoring ------------------------------------------------------------------------


def _scored(scene: Path, predictions: Path, mode: str = "corrected") -> dict[str, Any]:
    log = open_run(scene, source=SourceOptions(predictions=str(predictions)))
    return diagnose(log, make_params(mode)).to_json()


@pytest.mark.parametrize(
    ("bias", "error", "miss"),
    [((0.0, 0.0), 0.0, 0.0), ((0.0, 3.0), 3.0, 1.0), ((0.6, 0.8), 1.0, 0.0)],
)
def test_a_predictor_is_scored_against_the_realised_future(
    scene: Path, tmp_path: Path, bias: tuple[float, float], error: float, miss: float
) -> None:
    """Every step of every track off by ``bias``: ADE = FDE = |bias|; a miss is FDE > 2 m."""
    log = read_dlp_scene(scene)
    ego = log.metadata.raw["ego_agent"]["id"]
    write_predictions(log, tmp_path / "pred", bias=bias, ego_id=ego)
    scores = _scored(scene, tmp_path / "pred")["prediction_scores"]
    assert scores["ade"] == pytest.approx(error) and scores["fde"] == pytest.approx(error)
    assert scores["miss_rate"] == miss and scores["miss_threshold_m"] == 2.0
    assert set(scores["by_type"]) == {"Car", "Pedestrian"}
    assert scores["by_type"]["Pedestrian"]["ade"] == pytest.approx(error)


def test_steps_past_the_window_and_unknown_ids_are_not_scored(scene: Path, tmp_path: Path) -> None:
    """One hand-written file at 0.4 s: the reversing car (x 39.5, y -30 in the model's frame;
    the ego at 12, -20, yaw 0) predicted 1 m off at key "0", 2 m off at key "9", 100 m off at
    key "12" (past prediction_window 10: not scored); an id that is no actor."""
    number = ids()
    folder = tmp_path / "pred"
    folder.mkdir()
    car = {  # the car reverses 0.1 m a frame: at frame 10 + k + 1, x = 39.5 - 0.1 (k + 1)
        "0": {"x": 39.4 - 12 + 1.0, "y": -10.0, "z": 0.0},
        "9": {"x": 38.5 - 12, "y": -10.0 + 2.0, "z": 0.0},
        "12": {"x": 138.2 - 12, "y": -10.0, "z": 0.0},
    }
    (folder / "predictions-400.json").write_text(json.dumps({number[2]: car, "999": car}))
    document = _scored(scene, folder)
    frame = next(f for f in document["frames"] if f["timestamp_ms"] == 400)["prediction"]
    assert frame["scored_ids"] == 1 and frame["unmatched_ids"] == 1
    assert frame["ade"] == pytest.approx(1.5) and frame["fde"] == pytest.approx(2.0)
    assert frame["miss_rate"] == 0.0
    assert document["prediction_scores"]["scored"] == 1


def test_reference_mode_does_not_score(scene: Path, tmp_path: Path) -> None:
    log = read_dlp_scene(scene)
    write_predictions(log, tmp_path / "pred", ego_id=log.metadata.raw["ego_agent"]["id"])
    assert "prediction_scores" not in _scored(scene, tmp_path / "pred", "reference")


def test_bad_prediction_files_are_reported_and_the_rest_scored(scene: Path, tmp_path: Path) -> None:
    log = read_dlp_scene(scene)
    folder = write_predictions(log, tmp_path / "pred", bias=(0.0, 1.0))
    (folder / "predictions-400.json").write_text('{"1": ')
    (folder / "predictions-440.json").write_text('{"1": {"0": {"x": "far", "y": 0}}}')
    (folder / "notes.txt").write_text("ignored")
    document = _scored(scene, folder)
    problems = [f"{p['file']} {p['field']}: {p['issue']}" for p in document["input_problems"]]
    assert any(p.startswith("pred/predictions-400.json : invalid JSON") for p in problems)
    assert any("pred/predictions-440.json" in p and "'far'" in p for p in problems), problems
    assert document["prediction_scores"]["ade"] == pytest.approx(1.0)
    assert document["modules_judged"]["prediction"].startswith("not judged")


def test_predictions_elsewhere_or_missing_are_one_line(
    scene: Path, tmp_path: Path, log_dirs: Any
) -> None:
    for argv, expected in (
        ([str(scene), "--predictions", str(tmp_path / "none")], "no such folder of prediction"),
        (
            [str(log_dirs("cut_in", "planning")), "--predictions", str(tmp_path)],
            "--predictions applies to CARLA runs, DLP scenes and OpenLane-V2 segments",
        ),
    ):
        done = run_script("diagnose", *argv)
        assert done.returncode == 2 and expected in done.stderr, done.stderr
        assert len(done.stderr.strip().splitlines()) == 1


def test_a_predictor_node_beside_a_playing_scene_is_scored(
    ros_env: RosEnv, scene: Path, tmp_path: Path
) -> None:
    """Stack mode over DDS, each its own process: the test stack plays the scene (pose and
    actors), a predictor node (test/dlp_predictor.py) publishes constant-position
    predictions for each frame it hears, the monitors judge the stack's topics. Every
    frame's scores equal diagnose's of the same predictions given as files (by type, one
    "unknown": a stack sends no agent types): an actor's error k + 1 frames ahead is the
    distance it moved (the reversing car 0.1 m a frame). The parked car stands on car 1's
    path, so the aggregator's collision detection ends the run."""
    from stackgraph import latest_results, metrics_difference, run_stack_graph

    obstacles_file = scene.with_name(f"{STEM}_obstacles.json")
    _edit(
        obstacles_file, lambda d: [e.update(coords=[20.0, 20.0], heading=0.0) for e in d.values()]
    )
    log = read_dlp_scene(scene)
    ego = log.metadata.raw["ego_agent"]["id"]
    files = tmp_path / "constant"
    files.mkdir()
    for ts in log.frames:  # the same predictor, offline
        tracks = dlp_predictor.predictions(log.pose[ts], log.actors[ts], ego, 10)
        document = {
            i: {
                k: dict(zip("xyz", t.offsets[n].tolist(), strict=True))
                for n, k in enumerate(t.keys)
            }
            for i, t in tracks.items()
        }
        (files / f"predictions-{ts}.json").write_text(json.dumps(document))
    source = SourceOptions(derived_collision=True, predictions=str(files))
    offline = diagnose(open_run(scene, source=source), make_params("corrected"))
    assert offline.log.metadata.collision_frame == 27
    inputs = {f"inputs.{f}.layout": "none" for f in ("bboxes", "bboxes_gt", "waypoint")}
    inputs["inputs.predictions_with_perception.layout"] = "none"
    predictor = [sys.executable, str(Path(__file__).with_name("dlp_predictor.py"))]
    predictor += ["--namespace", ros_env.namespace, "--ego-id", ego]
    run = run_stack_graph(
        ros_env.env,
        tmp_path,
        str(scene),
        {
            "semantics": "corrected",
            "topic_namespace": ros_env.namespace,
            "timesteps_per_frame": 40,
            "ego_id": ego,
            "input_timeout_s": 30.0,
            "detect_collisions": True,
            **inputs,
        },
        [
            *("--namespace", ros_env.namespace, "--offset-ms", "0", "--jitter-ms", "0"),
            # the monitors, the aggregator and the predictor: a predictor matched late
            # misses the first frames, and the monitors wait for their predictions
            *("--wait-subscribers", "3"),
        ],
        companions={"predictor": predictor},
        after_publisher_s=90.0,
    )
    live = latest_results(run.results)
    keys = ("scored_ids", "unmatched_ids", "ade", "fde", "miss_rate")
    compared = 0
    for frame in offline.frames:
        want = frame.results["prediction"].metrics
        got = live.get(("prediction", frame.timestamp_ms))
        if got is None or not want.get("scored_ids"):
            continue
        difference = metrics_difference(
            {k: want[k] for k in keys}, {k: got.result.metrics[k] for k in keys}
        )
        assert difference is None, (frame.timestamp_ms, difference)
        # a stack sends no agent types: one "unknown" type, the frame's own figures
        overall = {k: got.result.metrics[k] for k in keys if k != "unmatched_ids"}
        assert got.result.metrics["by_type"] == {"unknown": overall}
        compared += 1
    assert compared >= 25, (compared, run.outputs)
    # frame 20: the reversing car (0.1 m a frame) scored up to the collision frame 27, so
    # keys 0..6 (errors 0.1 to 0.7 m, ADE 0.4), and the parked car (0 m)
    at_20 = next(f for f in offline.frames if f.timestamp_ms == 800).results["prediction"]
    car: Any = at_20.metrics["by_type"]
    car = car["Car"]
    assert car["scored_ids"] == 2 and car["ade"] == pytest.approx((0.4 + 0.0) / 2)
    assert car["fde"] == pytest.approx((0.7 + 0.0) / 2)


def test_frames_without_a_usable_time_are_one_line_however_many(scene: Path) -> None:
    frames_file = scene.with_name(f"{STEM}_frames.json")

    def untime(document: dict[str, Any]) -> None:
        for frame in range(10, 30):
            document[frame_token(frame)]["timestamp"] = "soon"

    _edit(frames_file, untime)
    log = read_dlp_scene(scene)
    lines = [p for p in problems_of(log) if "no time after the previous frame's" in p]
    assert len(lines) == 1 and "20 frames have no time" in lines[0], problems_of(log)
    assert len(log.frames) == FRAMES - 20
    assert not any("not on the list" in p for p in problems_of(log))


def test_convert_writes_a_scene_as_a_bag_that_diagnoses_the_same(
    scene: Path, tmp_path: Path
) -> None:
    bag, direct, again = tmp_path / "bag", tmp_path / "direct.json", tmp_path / "again.json"
    assert run_script("convert", str(scene), str(bag)).returncode == 0
    assert run_script("diagnose", str(scene), "--json", str(direct)).returncode == 0
    assert run_script("diagnose", str(bag), "--json", str(again)).returncode == 0
    first, second = json.loads(direct.read_text()), json.loads(again.read_text())
    for key in ("frames", "modules_judged", "verdict", "ego_id"):
        assert first[key] == second[key], key


def test_a_batch_job_diagnoses_a_scene_and_names_its_format(scene: Path) -> None:
    from ads_rca.batch.work import Job, run_job
    from ads_rca.sources.bag.options import BagOptions

    job = Job("s1", str(scene), make_params("corrected"), 64.0, BagOptions(), 60.0)
    outcome = run_job(job)
    assert outcome.row["format"] == "DLP scene" and not outcome.row.get("error"), outcome.row
    assert outcome.json is not None and json.loads(outcome.json)["frames"]
