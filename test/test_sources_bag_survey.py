"""Any rosbag2 bag listed without a profile: topics, types, counts, rates and spans from the
storage alone (no message decoded, no definition needed), each built-in profile's fit by
types and message counts, the recommendation, and a starting profile from the bag's types.

Real bags written with rosbags' writer and shaped like real recordings (a vehicle's sqlite3
file from before Iron: 320 declared topics, most without a message, legacy autoware_auto
types, no message_definitions table, no metadata.yaml), MCAP with and without its summary,
and the hostile ones: cut, damaged, lying metadata.yaml, names with control characters or
10 kB long.
"""

from __future__ import annotations

import math
import shutil
import sqlite3
from pathlib import Path

import pytest
import yaml
from writers.listing_bags import (
    EPOCH_NS,
    LEGACY_PERCEPTION,
    TopicSpec,
    every,
    odometry,
    storage_file,
    vehicle_topics,
    without_summary,
    write_bag,
)

from ads_rca.errors import InputError
from ads_rca.sources.bag.profiles import BUILTIN_PROFILES
from ads_rca.sources.bag.profiles.profile import Profile, load_profile
from ads_rca.sources.bag.profiles.recording import read_recording
from ads_rca.sources.bag.reader import NoRunMetadata, read_bag, split_order
from ads_rca.sources.bag.storage import (
    LISTED_BY_SALVAGE,
    LISTED_BY_SCAN,
    LISTED_BY_SQL,
    LISTED_BY_SUMMARY,
)
from ads_rca.sources.bag.survey import (
    BagSurvey,
    TopicInfo,
    listing_lines,
    picks,
    profile_lines,
    starting_profile,
    survey_bag,
)
from ads_rca.synth import synthesise
from ads_rca.synth.recording import write_recording

CARLA = "carla-autoware"
#: A type no package anywhere defines: listed, never decodable without --msg-path.
SECRET = "acme_perception_msgs/msg/Blobs"


def stack_profiles() -> list[Profile]:
    """Every built-in profile of a real stack (not this project's contract)."""
    loaded = [load_profile(name) for name in BUILTIN_PROFILES]
    return [profile for profile in loaded if not profile.contract]


def topic(survey: BagSurvey, name: str) -> TopicInfo:
    (found,) = [t for t in survey.topics if t.name == name]
    return found


@pytest.fixture(scope="module")
def vehicle(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A real vehicle's pre-Iron sqlite3 bag: 320 declared topics, no metadata.yaml."""
    topics = [*vehicle_topics(319), TopicSpec("/acme/blobs", SECRET, every(5, 1))]
    return write_bag(
        tmp_path_factory.mktemp("vehicle") / "drive", topics, pre_iron=True, metadata_yaml=False
    )


# --- listing ------------------------------------------------------------------------------


def test_a_pre_iron_vehicle_bag_lists_every_declared_topic(vehicle: Path) -> None:
    with sqlite3.connect(storage_file(vehicle)) as db:  # the fixture is shaped as claimed
        tables = {row[0] for row in db.execute("SELECT name FROM sqlite_master")}
    assert "message_definitions" not in tables and not (vehicle / "metadata.yaml").exists()
    survey = survey_bag(vehicle)
    assert survey.methods == (LISTED_BY_SQL,) and not survey.metadata_yaml
    assert len(survey.topics) == 320
    assert sum(1 for t in survey.topics if t.count == 0) == 315
    assert survey.message_count == 100 + 20 + 60 + 1 + 5
    odom = topic(survey, "/localization/kinematic_state")
    assert (odom.count, odom.first_ns, odom.last_ns) == (100, EPOCH_NS, EPOCH_NS + 99 * 20_000_000)
    assert odom.rate_hz == pytest.approx(50.0) and odom.span_s == pytest.approx(1.98)
    for name, msg_type in LEGACY_PERCEPTION.items():
        declared = topic(survey, name)
        assert (declared.type, declared.count, declared.rate_hz) == (msg_type, 0, None)
        assert declared.span_s is None
    assert (survey.first_ns, survey.last_ns) == (EPOCH_NS, EPOCH_NS + 99 * 20_000_000)
    assert not survey.stores_definitions and survey.problems == []
    assert SECRET in survey.undefined_types
    assert odom.definition == "standard"  # Kilted's layout: readable without --msg-path


def test_one_message_has_no_rate_and_nothing_is_infinite(vehicle: Path) -> None:
    single = topic(survey_bag(vehicle), "/autoware/state")
    assert (single.count, single.span_s, single.rate_hz) == (1, 0.0, None)
    document = single.to_dict()
    assert document["rate_hz"] is None and document["span_s"] == 0.0
    assert all(
        not isinstance(v, float) or math.isfinite(v)
        for t in survey_bag(vehicle).topics
        for v in t.to_dict().values()
    )


def test_the_listing_says_what_has_no_definition_and_how_to_supply_it(vehicle: Path) -> None:
    lines = listing_lines(survey_bag(vehicle))
    assert "topics: 320 (315 without messages)" in lines
    assert any(line.startswith("definitions: the bag stores none") for line in lines)
    said = next(line for line in lines if line.startswith("types without a definition"))
    assert "--msg-path DIR" in said
    assert f"  {SECRET}" in lines


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_with_and_without_metadata_yaml_the_listing_is_the_same(
    tmp_path: Path, storage: str
) -> None:
    topics = vehicle_topics(12)
    with_yaml = survey_bag(write_bag(tmp_path / "a", topics, storage))
    bare = survey_bag(write_bag(tmp_path / "b", topics, storage, metadata_yaml=False))
    assert with_yaml.metadata_yaml and not bare.metadata_yaml
    assert with_yaml.topics == bare.topics and with_yaml.problems == bare.problems == []
    assert with_yaml.stores_definitions  # rosbag2 >= Iron: the standard types' definitions


def test_an_mcap_without_summary_is_scanned_to_the_same_listing(tmp_path: Path) -> None:
    topics = vehicle_topics(40)
    bag = write_bag(tmp_path / "full", topics, "mcap", metadata_yaml=False)
    summarised = survey_bag(bag)
    assert summarised.methods == (LISTED_BY_SUMMARY,)
    without_summary(storage_file(bag))
    scanned = survey_bag(bag)
    assert scanned.methods == (LISTED_BY_SCAN,)
    assert scanned.topics == summarised.topics and scanned.problems == []


def test_a_cut_mcap_lists_what_it_holds_and_says_it_is_cut(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "cut", vehicle_topics(12), "mcap", metadata_yaml=False)
    data = storage_file(bag).read_bytes()
    storage_file(bag).write_bytes(data[: len(data) * 2 // 3])
    survey = survey_bag(bag)
    assert survey.methods == (LISTED_BY_SCAN,) and len(survey.topics) == 12
    assert 0 < survey.message_count < 181
    (cut,) = survey.problems
    assert "truncated after" in cut.issue and cut.file == storage_file(bag).name


def test_a_damaged_db3_is_listed_from_the_rows_it_still_yields(tmp_path: Path) -> None:
    topics = [TopicSpec("/odom", "nav_msgs/msg/Odometry", every(50, 40), odometry)]
    bag = write_bag(tmp_path / "damaged", topics, metadata_yaml=False)
    data = bytearray(storage_file(bag).read_bytes())
    middle = len(data) // 2 // 4096 * 4096
    data[middle : middle + 4096] = b"\xab" * 4096  # one page of the messages table
    storage_file(bag).write_bytes(bytes(data))
    survey = survey_bag(bag)
    assert survey.methods == (LISTED_BY_SALVAGE,)
    assert 0 < topic(survey, "/odom").count < 2000
    assert any("damaged after" in p.issue for p in survey.problems), survey.problems


def test_a_corrupt_db3_is_one_error_naming_the_file(tmp_path: Path) -> None:
    bag = tmp_path / "garbage"
    bag.mkdir()
    (bag / "x_0.db3").write_bytes(bytes(range(256)) * 64)
    with pytest.raises(InputError) as refused:
        survey_bag(bag)
    said = str(refused.value)
    assert said.startswith(f"{bag / 'x_0.db3'}: ") and "\n" not in said


def test_metadata_yaml_that_disagrees_is_said_and_the_storage_trusted(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "lying", vehicle_topics(8))
    path = bag / "metadata.yaml"
    document = yaml.safe_load(path.read_text())
    entries = document["rosbag2_bagfile_information"]["topics_with_message_count"]
    for entry in entries:
        meta = entry["topic_metadata"]
        if meta["name"] == "/localization/kinematic_state":
            entry["message_count"] = 999
        if meta["name"] == "/autoware/state":
            meta["type"] = "std_msgs/msg/String"
    entries.append(
        {"topic_metadata": {"name": "/ghost", "type": "std_msgs/msg/Empty"}, "message_count": 7}
    )
    path.write_text(yaml.safe_dump(document))
    survey = survey_bag(bag)
    assert topic(survey, "/localization/kinematic_state").count == 100  # the storage's
    assert "/ghost" not in {t.name for t in survey.topics}
    said = {(p.field, p.issue, p.action) for p in survey.problems}
    trusted = "the storage's own channels and types are used"
    assert (
        "/localization/kinematic_state",
        "message_count 999, the storage holds 100",
        trusted,
    ) in said
    assert (
        "/autoware/state",
        "type std_msgs/msg/String, the storage's is autoware_auto_system_msgs/msg/AutowareState",
        trusted,
    ) in said
    assert ("/ghost", "topic not in the storage files", "ignored") in said


def test_a_split_recording_without_metadata_yaml_lists_every_file(tmp_path: Path) -> None:
    first = write_bag(
        tmp_path / "a", [TopicSpec("/odom", "nav_msgs/msg/Odometry", every(10, 1), odometry)]
    )
    second = write_bag(
        tmp_path / "b",
        [
            TopicSpec("/odom", "nav_msgs/msg/Odometry", every(10, 1, EPOCH_NS + 10**9), odometry),
            TopicSpec("/late", "std_msgs/msg/String", (EPOCH_NS + 2 * 10**9,)),
        ],
    )
    split = tmp_path / "split"
    split.mkdir()
    shutil.copy(storage_file(first), split / "drive_0.db3")
    shutil.copy(storage_file(second), split / "drive_1.db3")
    survey = survey_bag(split)
    assert survey.files == ("drive_0.db3", "drive_1.db3")
    odom = topic(survey, "/odom")
    assert (odom.count, odom.first_ns, odom.last_ns) == (20, EPOCH_NS, EPOCH_NS + 1_900_000_000)
    assert topic(survey, "/late").count == 1
    names = [Path(f"x_{n}.db3") for n in (10, 2, 0, 1)]
    assert [p.name for p in split_order(names)] == ["x_0.db3", "x_1.db3", "x_2.db3", "x_10.db3"]


def test_hostile_names_are_escaped_and_cut_in_lines_and_kept_exact(tmp_path: Path) -> None:
    forged = "/evil\x1b[2J\nverdict: planning\u202e"
    long_name, long_type = "/x" * 5000, "acme_msgs/msg/" + "L" * 10_000
    topics = [
        TopicSpec(forged, "acme_msgs/msg/E\x1bvil", every(10, 1)),
        TopicSpec(long_name, long_type, every(10, 1)),
        *(TopicSpec(f"/empty/{i}", "std_msgs/msg/String") for i in range(300)),
    ]
    survey = survey_bag(write_bag(tmp_path / "hostile", topics, metadata_yaml=False))
    assert {t.name for t in survey.topics} >= {forged, long_name}  # exact in the data
    assert topic(survey, long_name).type == long_type
    assert {t["name"] for t in survey.to_dict()["topics"]} >= {forged, long_name}
    lines = listing_lines(survey) + profile_lines(survey)
    for line in lines:
        assert "\x1b" not in line and "\n" not in line and "\u202e" not in line, line
        assert len(line) < 400, line[:80]
    assert any("/evil\\x1b[2J\\x0averdict: planning" in line for line in lines)


# --- profiles -----------------------------------------------------------------------------


def profile_bag(path: Path, profile: Profile, silent: frozenset[str] = frozenset()) -> Path:
    """A bag of ``profile``'s topics in their first types, each with 10 messages but the
    ``silent`` inputs' (declared, no message)."""
    topics = [
        TopicSpec(spec.topic, spec.type, () if spec.input in silent else every(10, 1))
        for spec in profile.inputs.values()
    ]
    return write_bag(path, topics, metadata_yaml=False)


@pytest.mark.parametrize("profile", stack_profiles(), ids=lambda p: p.name)
def test_each_builtin_is_recommended_for_a_bag_of_its_types(
    tmp_path: Path, profile: Profile
) -> None:
    survey = survey_bag(profile_bag(tmp_path / "bag", profile))
    assert survey.recommendation is not None
    assert survey.recommendation.profile == profile.name, survey.recommendation
    (fit,) = [f for f in survey.fits if f.profile == profile.name]
    assert fit.mapped == tuple(profile.inputs) and not fit.refused
    with pytest.raises(NoRunMetadata, match=f"add --profile {profile.name}$"):
        read_bag(survey.path)  # the contract reader's hint: the same rule


@pytest.mark.parametrize("profile", stack_profiles(), ids=lambda p: p.name)
def test_declared_topics_without_messages_recommend_nothing(
    tmp_path: Path, profile: Profile
) -> None:
    """Every topic of the profile there, of its type, none with a message: the topic
    names alone (the old rule) would have named it."""
    silent = frozenset(profile.inputs)
    survey = survey_bag(profile_bag(tmp_path / "bag", profile, silent))
    assert survey.recommendation is not None and survey.recommendation.profile is None
    (fit,) = [f for f in survey.fits if f.profile == profile.name]
    assert fit.mapped == () and fit.refused.startswith("no message to time the frames by")
    assert {m.why for m in fit.inputs} == {"0 messages"}
    with pytest.raises(NoRunMetadata) as refused:
        read_bag(survey.path)
    assert "add --profile" not in str(refused.value)


def test_perception_without_messages_is_missing_not_mapped(tmp_path: Path) -> None:
    profile = load_profile(CARLA)
    perception = frozenset({"detections_3d", "tracked_objects", "predictions"})
    survey = survey_bag(profile_bag(tmp_path / "bag", profile, perception))
    (fit,) = [f for f in survey.fits if f.profile == CARLA]
    assert set(fit.missing) == perception
    assert {m.input: m.why for m in fit.inputs if not m.mapped} == dict.fromkeys(
        perception, "0 messages"
    )
    assert survey.recommendation is not None
    assert survey.recommendation.profile == CARLA  # on its ground truth, plan and control
    assert "detections_3d" not in survey.recommendation.reason
    assert "    declared, 0 messages: detections_3d, tracked_objects, predictions" in (
        profile_lines(survey)
    )


def test_a_bag_no_profile_fits_says_what_it_lacks(vehicle: Path) -> None:
    survey = survey_bag(vehicle, profiles=[load_profile(CARLA)])
    recommendation = survey.recommendation
    assert recommendation is not None and recommendation.profile is None
    assert "actors" in recommendation.lacking and "detections_3d" in recommendation.lacking
    assert recommendation.by_type["ego"] == ("/localization/kinematic_state",)
    lines = profile_lines(survey)
    assert "the bag holds no message of a type that carries:" in lines
    assert any(line.startswith("  actors (derived_object_msgs/msg/ObjectArray") for line in lines)
    assert "--write-profile FILE starts a profile of these topics for you to check" in lines


# --- a starting profile -------------------------------------------------------------------


@pytest.fixture(scope="module")
def renamed(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A carla-autoware recording (real messages), and the same with every topic renamed
    and no metadata.yaml: its types are the profile's, its names nobody's."""
    run = synthesise("lead_braking", "planning", 1)
    folder = tmp_path_factory.mktemp("renamed")
    original = folder / "original"
    write_recording(run, original, CARLA, "sqlite3")
    copy = Path(shutil.copytree(original, folder / "vehicle_a"))
    (copy / "metadata.yaml").unlink()
    with sqlite3.connect(storage_file(copy)) as db:
        db.execute("UPDATE topics SET name = '/vehicle_a' || name")
    return original, copy


def test_a_starting_profile_maps_each_input_by_type_and_reads_the_same_run(
    renamed: tuple[Path, Path], tmp_path: Path
) -> None:
    original, copy = renamed
    survey = survey_bag(copy)
    assert survey.recommendation is not None and survey.recommendation.profile is None
    path = tmp_path / "vehicle_a.yaml"
    path.write_text(starting_profile(survey, "vehicle-a"), encoding="utf-8")
    written = load_profile(path)
    builtin = load_profile(CARLA)
    assert written.name == "vehicle-a" and written.reference == "actors"
    assert {i: (s.topic, s.type) for i, s in written.inputs.items()} == {
        i: ("/vehicle_a" + s.topic, s.type) for i, s in builtin.inputs.items()
    }
    theirs = read_recording(original, CARLA)
    ours = read_recording(copy, written)
    assert ours.frames == theirs.frames and ours.metadata.collision_frame == (
        theirs.metadata.collision_frame
    )
    assert {i: s.state for i, s in ours.inputs.items()} == {
        i: s.state for i, s in theirs.inputs.items()
    }


def test_a_starting_profile_prefers_each_inputs_own_type(tmp_path: Path) -> None:
    detected = "autoware_perception_msgs/msg/DetectedObjects"
    tracked = "autoware_perception_msgs/msg/TrackedObjects"
    only_tracks = [
        TopicSpec("/odom", "nav_msgs/msg/Odometry", every(10, 1)),
        TopicSpec("/tracks", tracked, every(10, 1)),
    ]
    chosen = picks(survey_bag(write_bag(tmp_path / "a", only_tracks)).topics)
    assert chosen["tracked_objects"].name == "/tracks" and "detections_3d" not in chosen
    both = [
        *only_tracks,
        TopicSpec("/detections", detected, every(5, 1)),
        TopicSpec("/zz_more_tracks", tracked, every(20, 1)),
    ]
    chosen = picks(survey_bag(write_bag(tmp_path / "b", both)).topics)
    assert chosen["detections_3d"].name == "/detections"
    assert chosen["tracked_objects"].name == "/zz_more_tracks"  # the most messages


def test_a_starting_profile_leaves_ground_truth_and_silent_topics_to_the_user(
    tmp_path: Path,
) -> None:
    boxes = "vision_msgs/msg/Detection2DArray"
    topics = [
        TopicSpec("/odom", "nav_msgs/msg/Odometry", every(10, 1)),
        TopicSpec("/a_boxes", boxes, every(10, 1)),
        TopicSpec("/b_boxes", boxes, every(10, 1)),
        TopicSpec("/objects", "autoware_perception_msgs/msg/PredictedObjects"),  # 0 messages
    ]
    survey = survey_bag(write_bag(tmp_path / "bag", topics))
    text = starting_profile(survey, "mine")
    document = yaml.safe_load(text)
    assert document["reference"] == "ego"
    assert set(document["inputs"]) == {"ego", "detections_2d"}
    assert document["inputs"]["detections_2d"] == {"topic": "/a_boxes", "type": boxes}
    assert "  # ground_truth_2d: ground truth or the stack's output? set it by hand:" in text
    assert "  #   /b_boxes (vision_msgs/msg/Detection2DArray, 10 messages)" in text
    assert "  # predictions: no topic of its types has messages:" in text


def test_a_hostile_topic_name_loads_back_exactly(tmp_path: Path) -> None:
    forged = "/odom\x1b]0;x\x07:{a:b}#c"
    broken = "/odom\nactors: {topic: /x}"  # white space: no profile can name it
    topics = [
        TopicSpec(forged, "nav_msgs/msg/Odometry", every(10, 1)),
        TopicSpec(broken, "nav_msgs/msg/Odometry", every(20, 1)),
    ]
    survey = survey_bag(write_bag(tmp_path / "bag", topics))
    path = tmp_path / "p.yaml"
    path.write_text(starting_profile(survey, "p"), encoding="utf-8")
    loaded = load_profile(path)
    assert set(loaded.inputs) == {"ego"} and loaded.inputs["ego"].topic == forged
    text = path.read_text()
    assert text.isascii() and "\x1b" not in text and "\x07" not in text
    assert "    # also /odom\\x0aactors: {topic: /x} (nav_msgs/msg/Odometry, 20 messages)" in text


def test_a_bag_with_nothing_to_time_frames_by_starts_no_profile(tmp_path: Path) -> None:
    topics = [TopicSpec("/plan", "autoware_planning_msgs/msg/Trajectory", every(10, 1))]
    survey = survey_bag(write_bag(tmp_path / "bag", topics))
    with pytest.raises(
        InputError, match="no profile can be started: no message of a type that times the frames"
    ):
        starting_profile(survey, "p")
