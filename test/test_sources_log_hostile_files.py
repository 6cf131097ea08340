"""Hostile input: every case is a real file, run through the
real CLI in a subprocess, with a timeout (a hang fails the test) and an address-space limit
(reading /dev/zero until memory runs out fails the test instead of the machine).

- FIFOs, devices and symlinks to them named like log files; files over ``max_file_mb``.
- JSON nested deeper than the reader's limit (and deeper than the parsers' own).
- Output paths that are directories or cannot be written: refused before the work starts.
- ``metadata.json`` numbers given as strings, a collision frame past the last frame.
- Integers past the float range in every kind of file; file names with timestamps past
  ROS time's last millisecond.
- File names, folder names and paths with newlines and terminal escape sequences.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
from commandline import assert_clean, run_limited

from ads_rca.model import MAX_FRAME
from ads_rca.sources.log.writer import write_run_log
from ads_rca.synth import synthesise

if TYPE_CHECKING:
    from conftest import RosEnv

FORGED = "\nverdict: planning\n"
CLEAR_SCREEN = "\x1b[2J"


@pytest.fixture(scope="module")
def crash_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A synthesised crash with a planning fault (a verdict to protect), written once."""
    return write_run_log(
        synthesise("cut_in", "planning", seed=0), tmp_path_factory.mktemp("c") / "log"
    )


@pytest.fixture
def log_dir(crash_log: Path, tmp_path: Path) -> Path:
    """A private copy of the crash log, free to damage."""
    return Path(shutil.copytree(crash_log, tmp_path / "log"))


def _one(folder: Path, index: int = 3) -> Path:
    return sorted(folder.iterdir())[index]


def problems_of(done: subprocess.CompletedProcess[str]) -> list[dict[str, Any]]:
    """The problems of ``inspect --json`` output."""
    return list(json.loads(done.stdout)["problems"])


# --- only regular files, at most max_file_mb ------------------------------------------


@pytest.mark.parametrize("command", ["diagnose", "inspect", "convert"])
def test_a_fifo_named_like_a_record_file_is_reported_not_read(
    log_dir: Path, tmp_path: Path, command: str
) -> None:
    fifo = _one(log_dir / "pose")
    fifo.unlink()
    os.mkfifo(fifo)
    args = [command, str(log_dir)] + ([str(tmp_path / "bag")] if command == "convert" else [])
    done = run_limited(*args)
    assert_clean(done)
    if command == "convert":
        assert (tmp_path / "bag" / "metadata.yaml").is_file()
    else:
        assert f"pose/{fifo.name}: not a regular file (FIFO) (file skipped)" in done.stdout


def test_a_fifo_as_metadata_json_is_reported_and_defaults_used(log_dir: Path) -> None:
    (log_dir / "metadata.json").unlink()
    os.mkfifo(log_dir / "metadata.json")
    done = run_limited("inspect", "--json", str(log_dir))
    assert_clean(done)
    assert {
        "file": "metadata.json",
        "field": "",
        "issue": "not a regular file (FIFO)",
        "action": "file skipped",
        "severity": "error",
        "timestamp_ms": None,
    } in problems_of(done)


@pytest.mark.parametrize("device", ["/dev/zero", "/dev/urandom"])
@pytest.mark.parametrize("folder", ["actors", "bboxes", "metadata.json"])
def test_a_symlink_to_a_device_is_reported_and_the_rest_diagnosed(
    log_dir: Path, device: str, folder: str
) -> None:
    target = log_dir / folder if folder.endswith(".json") else _one(log_dir / folder)
    target.unlink()
    target.symlink_to(device)
    done = run_limited("diagnose", str(log_dir))
    assert_clean(done)
    name = target.relative_to(log_dir).as_posix()
    assert f"{name}: not a regular file (character device) (file skipped)" in done.stdout
    assert "frames judged" in done.stdout


def test_a_symlink_to_a_regular_file_is_still_read(log_dir: Path) -> None:
    original = _one(log_dir / "actors")
    moved = log_dir / "elsewhere.data"
    original.rename(moved)
    original.symlink_to(moved)
    done = run_limited("inspect", "--json", str(log_dir))
    assert_clean(done)
    assert not any(p["file"].endswith(original.name) for p in problems_of(done))


def test_a_file_over_max_file_mb_is_skipped_with_the_cap_named(log_dir: Path) -> None:
    big = _one(log_dir / "bboxes_gt")
    boxes = [{"id": i, "bounding_box": [[i, 1.5], [i + 10, 20.25]]} for i in range(40_000)]
    big.write_text(json.dumps(boxes))
    assert big.stat().st_size > 1 << 20
    expected = f"bboxes_gt/{big.name}: larger than 1 MB (max_file_mb) (file skipped)"
    for option in (["--max-file-mb", "1"], ["-p", "max_file_mb=1"]):
        done = run_limited("diagnose", str(log_dir), *option)
        assert_clean(done)
        assert expected in done.stdout
    done = run_limited("inspect", "--json", str(log_dir))  # the default cap is generous
    assert not any(p["issue"].startswith("larger than") for p in problems_of(done))


def test_max_file_mb_must_be_positive(log_dir: Path) -> None:
    done = run_limited("inspect", str(log_dir), "--max-file-mb", "0")
    assert_clean(done, 2)
    message = "parameter max_file_mb: 0 is out of range [0.001, 1048576] MB"
    assert done.stderr.strip().endswith(message)


@pytest.mark.parametrize("workers", ["0", "-3", "100000"])
def test_diagnose_workers_must_be_1_to_512(log_dir: Path, workers: str) -> None:
    """A typo is an error before the work, not a silent 1 or a fork bomb (batch's rule)."""
    done = run_limited("diagnose", str(log_dir), "--workers", workers)
    assert_clean(done, 2)
    assert done.stdout == ""
    assert done.stderr.strip() == f"ads-rca diagnose: error: --workers {workers}: expected 1 to 512"


@pytest.mark.parametrize("command", ["diagnose", "inspect"])
def test_max_problems_must_not_be_negative(log_dir: Path, command: str) -> None:
    """-5 printed all but the last five problems and called those five "more"."""
    done = run_limited(command, str(log_dir), "--max-problems", "-5")
    assert_clean(done, 2)
    assert done.stderr.strip() == f"ads-rca {command}: error: --max-problems -5: expected 0 or more"
    assert_clean(run_limited(command, str(log_dir), "--max-problems", "0"))


# --- JSON nested too deep ---------------------------------------------------------------


def _nested(depth: int) -> str:
    return "[" * depth + "1" + "]" * depth


#: (depth, folder, the limit named): parsers read 1024 levels; kept raw JSON 200.
DEEP_CASES = [
    (2000, "predictions", 1024),
    (100_000, "predictions", 1024),
    (2000, "bboxes", 1024),
    (100_000, "metadata.json", 1024),
    (300, "bboxes", 200),  # a box's extra field, kept and written again by convert
    (300, "metadata.json", 200),  # metadata.json is kept whole
]


def _write_nested(target: Path, depth: int) -> None:
    if target.parent.name == "bboxes":
        box = '{"id": 1, "bounding_box": [[1, 2], [3, 4]], "x": ' + _nested(depth) + "}"
        target.write_text("[" + box + "]")
    else:
        target.write_text('{"x": ' + _nested(depth) + "}")


@pytest.mark.parametrize(("depth", "folder", "limit"), DEEP_CASES)
def test_deeply_nested_json_is_reported_and_the_rest_diagnosed(
    log_dir: Path, tmp_path: Path, depth: int, folder: str, limit: int
) -> None:
    target = log_dir / folder if folder.endswith(".json") else _one(log_dir / folder)
    _write_nested(target, depth)
    name = target.relative_to(log_dir).as_posix()
    done = run_limited("diagnose", str(log_dir), "--max-problems", "50")
    assert_clean(done)
    assert f"{name}: invalid JSON (nested too deep: more than {limit} levels)" in done.stdout
    assert "frames judged" in done.stdout
    # What is kept can be written again: both conversions run through.
    assert_clean(run_limited("convert", str(log_dir), str(tmp_path / "bag")))
    assert_clean(run_limited("convert", str(tmp_path / "bag"), str(tmp_path / "back")))


@pytest.mark.parametrize(("depth", "reported"), [(198, False), (199, True)])
def test_a_box_extra_nested_at_the_kept_limit_is_judged_by_depth_not_by_brackets(
    log_dir: Path, depth: int, reported: bool
) -> None:
    """The reader walks a boxes file for deep extras only when its text has more than
    MAX_KEPT_DEPTH (200) brackets. An extra nested 199 levels inside a box inside the list
    is a document 201 deep: its fewest brackets are 1 + 1 + 199 = 201, walked and reported;
    198 levels (1 + 1 + 198 = 200 brackets, not walked) is within the limit either way."""
    from ads_rca.sources.log.reader import MAX_KEPT_DEPTH, read_run_log

    assert MAX_KEPT_DEPTH == 200
    target = _one(log_dir / "bboxes")
    target.write_text('[{"id": 1, "x": ' + _nested(depth) + "}]")
    issues = [p.issue for p in read_run_log(log_dir).problems if p.file.endswith(target.name)]
    assert ("invalid JSON (nested too deep: more than 200 levels)" in issues) is reported


def test_nesting_the_parser_reads_never_overflows_later(log_dir: Path, tmp_path: Path) -> None:
    """1000 levels: orjson reads it, but repr and json.dumps of it overflow Python's stack."""
    _write_nested(_one(log_dir / "predictions"), 1000)  # an unknown key: ignored
    _write_nested(_one(log_dir / "bboxes"), 150)  # kept, within the limit
    pose = _one(log_dir / "pose")
    document = json.loads(pose.read_text())
    pose.write_text(json.dumps(document)[:-1] + ', "x": ' + _nested(1000) + "}")
    done = run_limited("diagnose", str(log_dir), "--max-problems", "50")
    assert_clean(done)
    assert f"pose/{pose.name}: x: a list nested too deep is not a number" in done.stdout
    assert_clean(run_limited("convert", str(log_dir), str(tmp_path / "bag")))
    assert_clean(run_limited("convert", str(tmp_path / "bag"), str(tmp_path / "back")))


# --- output paths checked before the work -----------------------------------------------


def _unwritable_outputs(tmp_path: Path) -> dict[str, Path]:
    """Paths no process can write, root included (chmod does not stop root)."""
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    (tmp_path / "a_dir").mkdir()
    (tmp_path / "full_dir").mkdir()
    (tmp_path / "full_dir" / "x").write_text("x")
    return {
        "directory": tmp_path / "a_dir",
        "under a file": a_file / "sub" / "out.json",
        "in /proc": Path("/proc/ads_rca_out.json"),
    }


@pytest.mark.parametrize("case", ["directory", "under a file", "in /proc"])
@pytest.mark.parametrize("option", ["--json", "--report"])
def test_diagnose_refuses_an_unwritable_output_before_the_work(
    log_dir: Path, tmp_path: Path, option: str, case: str
) -> None:
    out = _unwritable_outputs(tmp_path)[case]
    done = run_limited("diagnose", str(log_dir), option, str(out))
    assert_clean(done, 2)
    assert done.stdout == ""  # refused before the diagnosis, not after it
    assert done.stderr.startswith(f"ads-rca diagnose: error: {option} {out}: ")
    assert len(done.stderr.splitlines()) == 1


def test_missing_parents_of_an_output_are_created_as_before(log_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "new" / "deeper" / "verdict.json"
    assert_clean(run_limited("diagnose", str(log_dir), "--json", str(out)))
    assert json.loads(out.read_text())["verdict"]


@pytest.mark.parametrize("case", ["a file", "not empty", "under a file", "in /proc"])
def test_convert_refuses_an_unwritable_out_before_reading(
    log_dir: Path, tmp_path: Path, case: str
) -> None:
    outputs = _unwritable_outputs(tmp_path)
    out = {
        "a file": tmp_path / "a_file",
        "not empty": tmp_path / "full_dir",
        "under a file": outputs["under a file"].parent,
        "in /proc": Path("/proc/ads_rca_out"),
    }[case]
    done = run_limited("convert", str(log_dir), str(out))
    assert_clean(done, 2)
    assert done.stdout == ""
    assert done.stderr.startswith(f"ads-rca convert: error: OUT {out}: ")


@pytest.mark.parametrize("case", ["directory", "under a file"])
def test_replay_refuses_an_unwritable_output_before_starting_the_graph(
    log_dir: Path, tmp_path: Path, ros_env: RosEnv, case: str
) -> None:
    out = _unwritable_outputs(tmp_path)[case]
    args = ["replay", str(log_dir), "--domain-id", str(ros_env.domain_id), "--timeout", "60"]
    done = run_limited(*args, "--json", str(out))
    assert_clean(done, 2)
    assert done.stdout == ""  # no graph was started
    assert done.stderr.startswith(f"ads-rca replay: error: --json {out}: ")
    record = tmp_path / "a_file" / "bag"
    done = run_limited(*args, "--record", str(record))
    assert_clean(done, 2)
    assert done.stdout == ""
    assert done.stderr.startswith(f"ads-rca replay: error: --record {record}: ")


# --- metadata.json numbers --------------------------------------------------------------


def _metadata(log_dir: Path) -> dict[str, Any]:
    return dict(json.loads((log_dir / "metadata.json").read_text()))


def _verdict(log_dir: Path, out: Path, semantics: str) -> dict[str, Any]:
    done = run_limited("diagnose", str(log_dir), "--semantics", semantics, "--json", str(out))
    assert_clean(done)
    return dict(json.loads(out.read_text()))


@pytest.mark.parametrize("semantics", ["reference", "corrected"])
def test_numbers_given_as_strings_are_used_and_reported(
    log_dir: Path, tmp_path: Path, semantics: str
) -> None:
    before = _verdict(log_dir, tmp_path / "before.json", semantics)
    metadata = _metadata(log_dir)
    for name in ("collision_frame", "timesteps_per_frame", "total_frames"):
        metadata[name] = str(metadata[name])
    (log_dir / "metadata.json").write_text(json.dumps(metadata))
    after = _verdict(log_dir, tmp_path / "after.json", semantics)
    problems = after.pop("input_problems")
    before.pop("input_problems")
    assert after == before  # the values are still used: the same verdict
    for name in ("collision_frame", "timesteps_per_frame", "total_frames"):
        value = metadata[name]
        assert {
            "file": "metadata.json",
            "field": name,
            "issue": f"{value!r} is a string, not a number",
            "action": f"value kept: {value}",
            "severity": "error",
            "timestamp_ms": None,
        } in problems


@pytest.mark.parametrize("semantics", ["reference", "corrected"])
def test_a_collision_frame_past_the_last_frame_is_reported_against_metadata(
    log_dir: Path, tmp_path: Path, semantics: str
) -> None:
    metadata = _metadata(log_dir)
    last_ms = max(int(p.stem.rpartition("-")[2]) for p in (log_dir / "actors").iterdir())
    metadata["collision_frame"] = last_ms // metadata["timesteps_per_frame"] + 30
    (log_dir / "metadata.json").write_text(json.dumps(metadata))
    document = _verdict(log_dir, tmp_path / "v.json", semantics)
    assert document["collision_frame"] == metadata["collision_frame"]  # still used
    past = [
        p
        for p in document["input_problems"]
        if p["file"] == "metadata.json" and p["field"] == "collision_frame"
    ]
    assert len(past) == 1 and "is past the last actors file" in past[0]["issue"], past


#: A JSON integer past the float range (JSON integers have no size limit; 1e999 reads as inf).
HUGE = int("9" * 400)


@pytest.mark.parametrize("semantics", ["reference", "corrected"])
def test_a_negative_collision_frame_other_than_minus_one(tmp_path: Path, semantics: str) -> None:
    """Only -1 means "no collision" to the reference (``collision_frame == -1``); at -5 it
    counts every failure as a collision (tried on the reference tool itself: the example
    log's controller, 80 safe at -1, is 80 collision at -5). Corrected finds no collision.
    Both say the frame is before the run."""
    example = Path(__file__).resolve().parents[1] / "examples" / "cut_in_perception"
    log_dir = Path(shutil.copytree(example, tmp_path / "log"))
    metadata = _metadata(log_dir)
    metadata["collision_frame"] = -1
    (log_dir / "metadata.json").write_text(json.dumps(metadata))
    none = _verdict(log_dir, tmp_path / "none.json", semantics)
    metadata["collision_frame"] = -5
    (log_dir / "metadata.json").write_text(json.dumps(metadata))
    before = _verdict(log_dir, tmp_path / "before.json", semantics)
    [said] = [p for p in before["input_problems"] if p["field"] == "collision_frame"]
    assert said["issue"].startswith("frame -5 is before the run") and said["action"] == "value kept"
    failures = {m: c["safe"] for m, c in none["modules"].items()}
    if semantics == "reference":
        assert sum(failures.values()) > 0
        assert all(c["collision"] == 0 for c in none["modules"].values())
        assert {m: (c["collision"], c["safe"]) for m, c in before["modules"].items()} == {
            m: (n, 0) for m, n in failures.items()
        }
        assert before["root_causes"] == [m for m, n in failures.items() if n]
    else:
        # A collision said to be before the run cannot be explained from the run: never
        # "no fault found (no collision)" (docs/verdicts.md).
        assert before["primary_root_cause"] is None and before["reason"] == "inconclusive"
        assert before["why_inconclusive"] == ["no frame of the effect window is in the run"]
        assert before["modules"] == none["modules"]
    assert before["collision"] == "yes" and before["conclusive"] is False
    report = tmp_path / "report.html"
    done = run_limited("diagnose", str(log_dir), "--semantics", semantics, "--report", str(report))
    assert "collision frame -5: before the run" in done.stdout
    assert "collision frame -5: before the run" in report.read_text()


@pytest.mark.parametrize("semantics", ["reference", "corrected"])
def test_integers_past_the_float_range_are_infinite_and_reported(
    log_dir: Path, tmp_path: Path, semantics: str
) -> None:
    """One huge integer in each kind of file: read as infinity (as ``1e999`` would be),
    reported against its file and field, the rest diagnosed; never an OverflowError."""

    def edit(path: Path, change: Any) -> str:
        document = json.loads(path.read_text())
        change(document)
        path.write_text(json.dumps(document))
        return f"{path.parent.name}/{path.name}"

    def first(document: dict[str, Any]) -> Any:
        """The first record of an object file."""
        return document[next(iter(document))]

    edited = {
        edit(_one(log_dir / "pose", 3), lambda d: d.update(x=HUGE)): "x",
        edit(_one(log_dir / "actors", 4), lambda d: first(d)["location"].update(y=-HUGE)): "y",
        edit(_one(log_dir / "waypoint", 5), lambda d: first(d).update(speed=HUGE)): "speed",
        edit(_one(log_dir / "predictions", 6), lambda d: first(first(d)).update(x=HUGE)): "x",
        edit(_one(log_dir / "control", 7), lambda d: d.update(acceleration=HUGE)): "acceleration",
    }
    metadata = _metadata(log_dir)
    metadata["collision_frame"] = HUGE
    metadata["ego_config"]["camera"]["camera_loc"] = [HUGE, 0, 1]
    (log_dir / "metadata.json").write_text(json.dumps(metadata))
    document = _verdict(log_dir, tmp_path / "v.json", semantics)
    problems = document["input_problems"]
    for file, field in edited.items():
        found = [p for p in problems if p["file"] == file and p["field"].endswith(field)]
        assert found and "9999999" in found[0]["issue"], (file, problems)
        assert re.search(r"is not (a )?finite( number)?$", found[0]["issue"]), found[0]
    by_field = {p["field"]: p for p in problems if p["file"] == "metadata.json"}
    assert by_field["collision_frame"]["issue"].endswith("is not an integer")
    assert "is not [x, y, z]" in by_field["ego_config.camera.camera_loc"]["issue"]
    assert all(len(p["issue"]) < 200 for p in problems)  # the value is shown cut short


def test_a_timestamp_past_ros_time_is_ignored_and_reported(log_dir: Path) -> None:
    """Int64 arrays of timestamps never see it; the folder's other files are read."""
    names = []
    for folder in ("actors", "pose"):
        huge = log_dir / folder / f"{folder}-{'9' * 30}.json"
        shutil.copy(_one(log_dir / folder, 0), huge)
        names.append(f"{folder}/{huge.name}")
    done = run_limited("diagnose", str(log_dir))
    assert_clean(done)
    assert "verdict: planning" in done.stdout
    done = run_limited("inspect", str(log_dir), "--json")
    assert_clean(done)
    issues = {p["file"]: p["issue"] for p in problems_of(done)}
    for name in names:
        assert issues[name] == "timestamp past the largest read (2147483647999 ms)"


@pytest.mark.parametrize("semantics", ["reference", "corrected"])
def test_a_frame_period_past_ros_time_is_reported_and_inferred(
    log_dir: Path, tmp_path: Path, semantics: str
) -> None:
    """``timesteps_per_frame`` of 10**23 overflowed the int64 arrays of the frame checks;
    it is reported and the period inferred from the file names, as for a missing one."""
    before = _verdict(log_dir, tmp_path / "before.json", semantics)
    metadata = _metadata(log_dir)
    metadata["timesteps_per_frame"] = 10**23
    (log_dir / "metadata.json").write_text(json.dumps(metadata))
    after = _verdict(log_dir, tmp_path / "after.json", semantics)
    [period] = [p for p in after["input_problems"] if p["field"] == "timesteps_per_frame"]
    assert period["issue"].endswith("is past the largest read (2147483647999)"), period
    assert period["action"].startswith("default used")
    assert after["primary_root_cause"] == before["primary_root_cause"]
    metadata["timesteps_per_frame"] = 50
    metadata["collision_frame"] = 10**9  # past the last frame
    (log_dir / "metadata.json").write_text(json.dumps(metadata))
    past = _verdict(log_dir, tmp_path / "past.json", semantics)
    metadata["total_frames"] = metadata["collision_frame"] = 10**300
    (log_dir / "metadata.json").write_text(json.dumps(metadata))
    huge = _verdict(log_dir, tmp_path / "huge.json", semantics)
    # Clamped to the largest frame (the live graph's messages carry it; int64 holds it),
    # said, and judged as any frame past the log is.
    assert huge["collision_frame"] == MAX_FRAME
    said = {(p["field"], p["issue"].split()[-1], p["action"]) for p in huge["input_problems"]}
    assert ("collision_frame", "read", f"default used: {MAX_FRAME}") in said  # clamped
    assert ("collision_frame", "ms)", "value kept") in said  # and past the last actors file
    assert ("total_frames", str(MAX_FRAME), "default used: 99") in said
    keys = ("primary_root_cause", "root_causes", "contributing", "evidence")
    assert {k: huge[k] for k in keys} == {k: past[k] for k in keys}
    metadata["collision_frame"] = -(10**300)
    (log_dir / "metadata.json").write_text(json.dumps(metadata))
    below = _verdict(log_dir, tmp_path / "below.json", semantics)
    assert below["collision_frame"] == -MAX_FRAME


@pytest.mark.parametrize("semantics", ["reference", "corrected"])
def test_step_keys_past_int64_are_no_step(log_dir: Path, tmp_path: Path, semantics: str) -> None:
    """A prediction step or plan point keyed by a 23-digit integer: no step (as a key that
    is not an integer), never an OverflowError inside a check."""
    before = _verdict(log_dir, tmp_path / "before.json", semantics)
    for folder, point in (
        ("predictions", {"x": 1.0, "y": 2.0, "z": 0.0}),
        ("waypoint", {"x": 1.0, "y": 2.0, "speed": 0.0}),
    ):
        for file in sorted((log_dir / folder).iterdir())[::3]:
            document = json.loads(file.read_text())
            for steps in document.values() if folder == "predictions" else [document]:
                steps["9" * 23] = point
            file.write_text(json.dumps(document))
    after = _verdict(log_dir, tmp_path / "after.json", semantics)
    failed = [p for p in after["input_problems"] if "check failed" in p["issue"]]
    assert not failed, failed[:3]
    assert after["primary_root_cause"] == before["primary_root_cause"]


@pytest.mark.parametrize("semantics", ["reference", "corrected"])
def test_the_largest_doubles_are_judged_without_numpy_warnings(
    log_dir: Path, tmp_path: Path, semantics: str
) -> None:
    """1.7e308 is a valid JSON number: products and differences of it overflow in every
    rule; what they make (inf, NaN) is judged, and nothing but the verdict is printed."""
    big = 1.7e308
    metadata = _metadata(log_dir)
    metadata["ego_config"]["camera"]["camera_loc"] = [big, -big, big]
    (log_dir / "metadata.json").write_text(json.dumps(metadata))
    for index in range(20, 40, 3):
        boxes = _one(log_dir / "bboxes", index)
        document = json.loads(boxes.read_text())
        document.append({"id": big, "bounding_box": [[-big, -big], [big, big]]})
        boxes.write_text(json.dumps(document))
        pose = _one(log_dir / "pose", index)
        document = json.loads(pose.read_text())
        document.update(x=big, yaw=big, speed=-big)
        pose.write_text(json.dumps(document))
    out = tmp_path / "v.json"
    done = run_limited(
        "diagnose", str(log_dir), "--semantics", semantics, "--json", str(out),
        "--report", str(tmp_path / "r.html"),
    )  # fmt: skip
    assert_clean(done)
    assert "Warning" not in done.stderr and "overflow" not in done.stderr, done.stderr
    assert json.loads(out.read_text())["frames"]  # judged, frame by frame


# --- control characters never reach the terminal raw ------------------------------------


def _terminal_safe(text: str) -> None:
    """No escape sequence, no bidi override, at most the one real verdict line."""
    assert "\x1b" not in text and "\u202e" not in text
    assert sum(line.startswith("verdict:") for line in text.splitlines()) <= 1


def test_forged_lines_and_escapes_in_file_names_are_escaped(log_dir: Path, tmp_path: Path) -> None:
    """The real verdict is planning too: a forged line would be indistinguishable."""
    (log_dir / "actors" / f"evil{FORGED}.json").write_text("{}")
    (log_dir / "pose" / f"{CLEAR_SCREEN}.json").write_text("{}")
    for args in (
        ["diagnose", str(log_dir), "--json", str(tmp_path / "v.json")],
        ["inspect", str(log_dir)],
    ):
        done = run_limited(*args)
        assert_clean(done)
        _terminal_safe(done.stdout)
        assert "actors/evil\\x0averdict: planning\\x0a.json: file name" in done.stdout
        assert "pose/\\x1b[2J.json: file name" in done.stdout
        lines = done.stdout.splitlines()
        assert sum(line.startswith("verdict:") for line in lines) == (args[0] == "diagnose")
    # JSON keeps the exact names (JSON escapes them itself).
    files = {p["file"] for p in json.loads((tmp_path / "v.json").read_text())["input_problems"]}
    assert {f"actors/evil{FORGED}.json", f"pose/{CLEAR_SCREEN}.json"} <= files


def test_a_log_folder_name_cannot_forge_lines(crash_log: Path, tmp_path: Path) -> None:
    log_dir = Path(shutil.copytree(crash_log, tmp_path / f"log{FORGED}{CLEAR_SCREEN}"))
    done = run_limited("diagnose", str(log_dir))
    assert_clean(done)
    _terminal_safe(done.stdout)
    assert sum(line.startswith("verdict:") for line in done.stdout.splitlines()) == 1
    missing = run_limited("inspect", str(tmp_path / f"nothing{FORGED}{CLEAR_SCREEN}"))
    assert_clean(missing, 2)
    assert len(missing.stderr.splitlines()) == 1 and "\x1b" not in missing.stderr


def test_ids_and_field_values_from_a_log_are_escaped(log_dir: Path) -> None:
    actors = _one(log_dir / "actors")
    document = json.loads(actors.read_text())
    document[f"id{FORGED}\u202e"] = {"location": {"x": "far\x1b[31m", "y": 0}}
    actors.write_text(json.dumps(document))
    done = run_limited("diagnose", str(log_dir), "--max-problems", "50")
    assert_clean(done)
    _terminal_safe(done.stdout)
    assert "id\\x0averdict: planning\\x0a\\u202e.location.x: 'far\\x1b[31m' is not a number" in (
        done.stdout
    )


def test_printable_escapes_every_control_and_keeps_text() -> None:
    from ads_rca.foundation.text import printable

    assert printable("a\nb\r\t\x00\x7f\x85\x9b") == "a\\x0ab\\x0d\\x09\\x00\\x7f\\x85\\x9b"
    assert printable("\u2028\u2029\u202e\u2066\u200f") == "\\u2028\\u2029\\u202e\\u2066\\u200f"
    assert printable("naïve → café 🚗 \\x0a") == "naïve → café 🚗 \\x0a"
    assert printable("\ud800a\udfff") == "\\ud800a\\udfff"  # lone surrogates


@pytest.mark.parametrize("semantics", ["reference", "corrected"])
def test_lone_surrogates_in_ids_and_keys_are_escaped_everywhere(
    log_dir: Path, tmp_path: Path, semantics: str
) -> None:
    """JSON's ``"\\ud800"`` parses to a lone surrogate, which no terminal or UTF-8 file can
    take (the summary and the HTML report raised UnicodeEncodeError): escaped on the
    terminal and in the report, kept exactly (as JSON escapes) in the verdict JSON."""
    for index in range(30, 40):
        boxes = _one(log_dir / "bboxes_gt", index)
        document = json.loads(boxes.read_text())
        document.append({"id": "\ud800evil", "bounding_box": [[1, 2], [30, 40]], "l\udfff": 1})
        boxes.write_text(json.dumps(document))
        predictions = _one(log_dir / "predictions_with_perception", index)
        document = json.loads(predictions.read_text())
        document["\udc00ghost"] = {"0": {"x": 1.0, "y": 2.0, "z": 0.0}}
        predictions.write_text(json.dumps(document))
    out, report = tmp_path / "v.json", tmp_path / "r.html"
    args = ["--semantics", semantics, "--json", str(out), "--report", str(report)]
    done = run_limited("diagnose", str(log_dir), *args, "--max-problems", "100")
    assert_clean(done)
    assert "\\udc00ghost" in done.stdout
    assert "\\udc00ghost" in report.read_text(encoding="utf-8")
    document = json.loads(out.read_text())
    issues = [p["issue"] for p in document["input_problems"]]
    assert any(r"id '\udc00ghost' is not an actor" in issue for issue in issues)  # repr'd


def test_replay_plays_a_log_with_timestamps_at_and_past_the_end_of_ros_time(
    log_dir: Path, tmp_path: Path, ros_env: RosEnv
) -> None:
    """A frame at ROS time's last millisecond is played (its seconds fill the int32); one
    a millisecond later is reported and not read (the player died on it: struct.error)."""
    last = 2**31 * 1000 - 1
    past: set[str] = set()
    for folder in ("actors", "pose", "bboxes", "bboxes_gt", "waypoint"):
        first = _one(log_dir / folder, 0)
        prefix = first.name.rpartition("-")[0]
        for ts in (last, last + 1):
            shutil.copy(first, log_dir / folder / f"{prefix}-{ts}.json")
        past.add(f"{folder}/{prefix}-{last + 1}.json")
    out = tmp_path / "v.json"
    args = ["replay", str(log_dir), "--domain-id", str(ros_env.domain_id), "--timeout", "90"]
    done = run_limited(*args, "--json", str(out))
    assert_clean(done)
    problems = json.loads(out.read_text())["input_problems"]
    assert {p["file"] for p in problems if p["issue"].startswith("timestamp past")} == past


def test_replay_player_skips_a_fifo_and_honours_max_file_mb(
    log_dir: Path, tmp_path: Path, ros_env: RosEnv
) -> None:
    """The live graph's player reads with the same rules; ``max_file_mb`` reaches it."""
    fifo = _one(log_dir / "pose")
    fifo.unlink()
    os.mkfifo(fifo)
    big = _one(log_dir / "bboxes_gt", 5)
    big.write_text(
        json.dumps([{"id": i, "bounding_box": [[i, 1], [i + 9, 20]]} for i in range(40_000)])
    )
    out = tmp_path / "v.json"
    config = tmp_path / "reader.yaml"  # the YAML key, same name as the flag and ROS parameter
    config.write_text("max_file_mb: 1\n")
    args = ["replay", str(log_dir), "--domain-id", str(ros_env.domain_id), "--timeout", "90"]
    done = run_limited(*args, "--config", str(config), "--json", str(out))
    assert_clean(done)
    issues = {(p["file"], p["issue"]) for p in json.loads(out.read_text())["input_problems"]}
    assert (f"pose/{fifo.name}", "not a regular file (FIFO)") in issues
    assert (f"bboxes_gt/{big.name}", "larger than 1 MB (max_file_mb)") in issues
