"""Bags nobody checked: cut files, damaged messages, a metadata.yaml that lies, a killed
recorder. Real bags of the example log (written by ``ads-rca convert`` or recorded over DDS),
really cut and really damaged on disk; every case must give a diagnosis that says what was
lost, or one error line (exit 2), never a traceback or a silent partial read."""

from __future__ import annotations

import json
import os
import shutil
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

import pytest
import yaml
from commandline import assert_clean, convert_example, run_limited
from rosrun import start_player, start_recorder

from ads_rca.cli import main as cli
from ads_rca.contract import topics
from ads_rca.errors import InputError
from ads_rca.model import RunLog
from ads_rca.ros.launcher import Launcher
from ads_rca.sources.bag.mcap_writer import McapBagWriter
from ads_rca.sources.bag.reader import iter_mcap_stream, load_bag, read_bag

if TYPE_CHECKING:
    from conftest import RosEnv

pytestmark = pytest.mark.timeout(600)

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "cut_in_perception"
ADS_RCA = Path(sys.executable).parent / "ads-rca"
CUT = "the messages before the cut are used"
#: MCAP's opcode of a message index record, and how many of them one cut sample stands for.
MESSAGE_INDEX = 0x07
MESSAGE_INDEX_STRIDE = 10


@pytest.fixture(scope="module")
def bags(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("hostile")
    return {
        "zstd": convert_example(root / "zstd", "--chunk-size", "16384"),
        "zstd_1MiB": convert_example(root / "zstd_1MiB"),
        "none": convert_example(root / "none", "--chunk-size", "16384", "--compression", "none"),
        "lz4": convert_example(root / "lz4", "--chunk-size", "16384", "--compression", "lz4"),
        "sqlite3": convert_example(root / "sqlite3", "--storage", "sqlite3"),
    }


def storage_file(bag: Path) -> Path:
    return next(p for p in bag.iterdir() if p.suffix in (".mcap", ".db3"))


def copy_bag(bag: Path, out: Path, data: bytes, with_yaml: bool = True) -> Path:
    """A copy of ``bag`` whose storage file holds ``data`` (with or without metadata.yaml)."""
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    (out / storage_file(bag).name).write_bytes(data)
    if with_yaml:
        shutil.copy(bag / "metadata.yaml", out / "metadata.yaml")
    return out


def record_offsets(data: bytes) -> list[tuple[int, int, int]]:
    """(offset, opcode, length) of every top-level MCAP record."""
    out, pos = [], 8
    while pos + 9 <= len(data):
        opcode, length = struct.unpack_from("<BQ", data, pos)
        out.append((pos, opcode, length))
        pos += 9 + length
        if opcode == 2:  # footer
            break
    return out


def cut_problems(log: RunLog) -> list[str]:
    return [str(p) for p in log.problems if CUT in p.action]


def recovered(problem: str) -> int:
    """N of a "truncated after B bytes: N messages recovered" problem."""
    return int(problem.split("bytes: ")[1].split(" ", maxsplit=1)[0])


def verdict(path: Path, capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = cli(["diagnose", str(path), "--workers", "1"])
    out, err = capsys.readouterr()
    return code, out, err


# --- truncated storage files --------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["zstd", "none", "lz4"])
@pytest.mark.parametrize("with_yaml", [True, False])
def test_every_cut_of_an_mcap_is_said(
    bags: dict[str, Path], tmp_path: Path, kind: str, with_yaml: bool
) -> None:
    """Cut at and around every record boundary, in the middle of every record, at 0 and 8
    bytes and just before the end magic: either a log with a truncation problem saying how
    many messages were kept, or one InputError. Message indexes (nine after each chunk,
    three quarters of the records, alike but for their counts) are cut around every
    :data:`MESSAGE_INDEX_STRIDE`-th one, the first and the last."""
    bag = bags[kind]
    data = storage_file(bag).read_bytes()
    total = len(list(iter_mcap_stream(storage_file(bag))))
    cuts = {0, 1, 8, 9, 20, len(data) - 8, len(data) - 1}
    records = record_offsets(data)
    indexes = [offset for offset, opcode, _n in records if opcode == MESSAGE_INDEX]
    sampled = {*indexes[::MESSAGE_INDEX_STRIDE], indexes[-1]}
    assert len(indexes) > 5 * len(sampled)
    for offset, opcode, length in records:
        if opcode != MESSAGE_INDEX or offset in sampled:
            cuts |= {offset - 1, offset + 1, offset + 9 + length // 2}
    outcomes = {"error": 0, "partial": 0}
    for cut in sorted(c for c in cuts if 0 <= c < len(data)):
        copy = copy_bag(bag, tmp_path / "cut", data[:cut], with_yaml)
        try:  # the storage level (fast); read_bag hands these problems on (below, and CLI)
            problems = load_bag(copy).problems
        except InputError as error:
            assert "\n" not in str(error)
            outcomes["error"] += 1
            continue
        said = [str(p) for p in problems if CUT in p.action]
        assert len(said) == 1, (cut, [str(p) for p in problems][:5])
        assert f"truncated after {cut} bytes" in said[0], said
        assert storage_file(bag).name in said[0]
        assert recovered(said[0]) <= total
        if with_yaml:  # metadata.yaml's count is quoted
            assert f"of {total} (metadata.yaml)" in said[0], said
        outcomes["partial"] += 1
    assert outcomes["error"] and outcomes["partial"] > 20, outcomes
    for cut in (len(data) // 3, len(data) * 2 // 3, len(data) - 8):
        log = read_bag(copy_bag(bag, tmp_path / "cut", data[:cut], with_yaml))
        (cut_said,) = cut_problems(log)
        assert f"truncated after {cut} bytes" in cut_said


def test_cut_mcap_through_the_command_line(
    bags: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = bags["none"]
    data = storage_file(bag).read_bytes()
    code, full, _ = verdict(bag, capsys)
    assert code == 0 and "verdict: perception" in full and "input problems: 0" in full
    chunks = [o for o, opcode, _n in record_offsets(data) if opcode == 6]
    middle_of_a_chunk = chunks[len(chunks) // 2] + 2000
    for cut, with_yaml in [(middle_of_a_chunk, True), (middle_of_a_chunk, False)]:
        copy = copy_bag(bag, tmp_path / f"cut{with_yaml}", data[:cut], with_yaml)
        code, out, err = verdict(copy, capsys)
        assert code == 0 and "Traceback" not in err, err
        assert f"truncated after {cut} bytes" in out and "verdict:" in out, out
        assert cli(["inspect", str(copy), "--json"]) == 0
        listed = json.loads(capsys.readouterr().out)["problems"]
        assert any("truncated after" in p["issue"] for p in listed), listed
    # Only the end magic missing: everything is there, and still said.
    copy = copy_bag(bag, tmp_path / "nomagic", data[:-8])
    code, out, _ = verdict(copy, capsys)
    assert code == 0 and "verdict: perception" in out
    assert f"footer: truncated after {len(data) - 8} bytes: 732 of 732" in out, out
    copy = copy_bag(bag, tmp_path / "toconvert", data[:middle_of_a_chunk])
    assert cli(["convert", str(copy), str(tmp_path / "converted")]) == 0
    assert f"truncated after {middle_of_a_chunk} bytes" in capsys.readouterr().err
    for cut in (0, 8):  # nothing readable: one line, exit 2
        copy = copy_bag(bag, tmp_path / f"tiny{cut}", data[:cut])
        code, out, err = verdict(copy, capsys)
        assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err
        assert "not an MCAP file" in err or "truncated before the first record" in err


def test_partial_chunk_messages_are_recovered(bags: dict[str, Path], tmp_path: Path) -> None:
    """A cut inside a chunk keeps the chunk's complete messages (zstd: its whole blocks of
    128 KiB, so a chunk of 1 MiB)."""
    for kind in ("none", "zstd_1MiB"):
        data = storage_file(bags[kind]).read_bytes()
        first_chunk = next((o, n) for o, opcode, n in record_offsets(data) if opcode == 6)
        cut = first_chunk[0] + 9 + first_chunk[1] * 3 // 4
        log = read_bag(copy_bag(bags[kind], tmp_path / kind, data[:cut]))
        (said,) = cut_problems(log)
        assert recovered(said) > 0, said


def test_cut_sqlite3_is_said(bags: dict[str, Path], tmp_path: Path) -> None:
    bag = bags["sqlite3"]
    data = storage_file(bag).read_bytes()
    page = struct.unpack_from(">H", data, 16)[0]
    cuts = [0, 50, 100, page, 5 * page + 10, len(data) // 2, len(data) - page, len(data) - 1]
    partial = 0
    for cut in cuts:
        copy = copy_bag(bag, tmp_path / "cut", data[:cut])
        try:
            log = read_bag(copy)
        except InputError as error:
            assert "\n" not in str(error)
            continue
        said = cut_problems(log)
        assert len(said) == 1 and f"truncated after {cut} bytes" in said[0], said
        partial += 1
    assert partial >= 3


# --- damaged messages ---------------------------------------------------------------------


def flip(data: bytes, start: int, n: int = 50) -> bytes:
    out = bytearray(data)
    for i in range(start, min(start + n, len(out))):
        out[i] ^= 0xFF
    return bytes(out)


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["none", "sqlite3"])
def test_damaged_messages_are_skipped_and_said(
    bags: dict[str, Path], tmp_path: Path, kind: str
) -> None:
    """50 flipped bytes at several places of real messages: the bag is still judged; a
    message that cannot be decoded is skipped and named (topic, log time)."""
    bag = bags[kind]
    data = storage_file(bag).read_bytes()
    messages = list(iter_mcap_stream(storage_file(bags["none"])))
    skipped = 0
    for message in messages[5::106]:
        if message.topic.endswith(topics.METADATA):
            continue
        at = data.find(message.data)
        if at < 0 or data.rfind(message.data) != at:  # spread over sqlite pages, or not unique
            continue
        for fraction in (0.1, 0.5, 0.9):
            start = at + int(len(message.data) * fraction)  # 50 bytes, inside this message
            damaged = flip(data, start, min(50, at + len(message.data) - start))
            log = read_bag(copy_bag(bag, tmp_path / "flip", damaged))
            assert len(log.frames) >= 80
            named = [p for p in log.problems if p.action == "message skipped"]
            for p in named:
                assert p.field == message.topic and str(message.log_time_ns) in p.issue, p
            if kind != "sqlite3":  # MCAP chunks carry a CRC: damage is said even when the
                assert any("CRC mismatch" in p.issue for p in log.problems)  # bytes decode
            skipped += len(named)
    assert skipped >= 5


def test_absurd_lengths_are_refused_not_allocated(tmp_path: Path) -> None:
    """A sequence count of 2**31 in a MarkerArray, a chunk claiming 2**40 bytes: refused."""
    bag = convert_example(tmp_path / "bag", "--compression", "none", "--chunk-size", "16384")
    mcap = storage_file(bag)
    messages = list(iter_mcap_stream(mcap))
    actors = next(m for m in messages if m.topic.endswith("/" + topics.ACTORS))
    huge = actors.data[:4] + struct.pack("<I", 2**31) + actors.data[8:]
    data = mcap.read_bytes()
    at = data.find(actors.data)
    damaged = data[:at] + huge + data[at + len(huge) :]
    log = read_bag(copy_bag(bag, tmp_path / "huge", damaged))
    (p,) = [p for p in log.problems if p.action == "message skipped"]
    assert p.field == actors.topic and "Invalid sequence length 2147483648" in p.issue
    # A chunk (not the first: it holds run/metadata) whose size field claims a terabyte.
    offset = [o for o, opcode, _n in record_offsets(data) if opcode == 6][1]
    claim = data[: offset + 9 + 16] + struct.pack("<Q", 2**40) + data[offset + 9 + 24 :]
    log = read_bag(copy_bag(bag, tmp_path / "claim", claim))
    assert any("declares 1099511627776 uncompressed bytes" in p.issue for p in log.problems)
    # ... and a record length of 2**62 in the middle of the file.
    second = [o for o, opcode, _n in record_offsets(data) if opcode == 6][1]
    longer = data[: second + 1] + struct.pack("<Q", 2**62) + data[second + 9 :]
    log = read_bag(copy_bag(bag, tmp_path / "longer", longer))
    assert len(cut_problems(log)) == 1


def test_damaged_bag_through_diagnose_subprocess(bags: dict[str, Path], tmp_path: Path) -> None:
    bag = bags["none"]
    data = storage_file(bag).read_bytes()
    messages = list(iter_mcap_stream(storage_file(bag)))
    target = [m for m in messages if m.topic.endswith("/" + topics.TRAJECTORY)][3]
    at = data.find(target.data)
    damaged = flip(data, at + int(len(target.data) * 0.1))
    copy = copy_bag(bag, tmp_path / "flip", damaged)
    run = subprocess.run(
        [str(ADS_RCA), "diagnose", str(copy), "--workers", "1"],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert run.returncode == 0 and "Traceback" not in run.stderr, run.stderr
    assert "verdict: perception" in run.stdout
    assert f"{target.topic}: message at log time {target.log_time_ns} ns" in run.stdout


def test_a_bag_with_a_hostile_size_field_in_a_string(tmp_path: Path) -> None:
    """A writer's bag with one garbage message among good ones: the good ones are used."""
    bag = tmp_path / "bag"
    name = topics.topic_name(topics.METADATA)
    with McapBagWriter(bag, compression="none") as writer:
        writer.add_topic(name, "std_msgs/msg/String")
        writer.write(name, 1, b"\x00\x01\x00\x00" + struct.pack("<I", 2**32 - 1) + b"x" * 8)
    with pytest.raises(InputError, match="Invalid string length"):
        read_bag(bag)  # the only metadata is garbage: one line naming why


# --- a metadata.yaml that lies ------------------------------------------------------------


@pytest.mark.parametrize("kind", ["zstd", "sqlite3"])
def test_lying_metadata_yaml_is_said_and_ignored(
    bags: dict[str, Path], tmp_path: Path, kind: str, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = tmp_path / "lie"
    shutil.copytree(bags[kind], bag)
    path = bag / "metadata.yaml"
    document = yaml.safe_load(path.read_text())
    info = document["rosbag2_bagfile_information"]
    actors, detections = (topics.topic_name(k) for k in (topics.ACTORS, topics.DETECTIONS))
    entries = [
        e for e in info["topics_with_message_count"] if e["topic_metadata"]["name"] != actors
    ]
    for entry in entries:
        if entry["topic_metadata"]["name"] == detections:
            entry["topic_metadata"]["type"] = "std_msgs/msg/String"
    entries.append(
        {
            "topic_metadata": {
                "name": "/ghost",
                "type": "std_msgs/msg/String",
                "serialization_format": "cdr",
            },
            "message_count": 3,
        }
    )
    info["topics_with_message_count"] = entries
    path.write_text(yaml.safe_dump(document))
    original, lied = read_bag(bags[kind]), read_bag(bag)
    assert len(lied.actors) == len(original.actors) == 81
    assert len(lied.bboxes) == len(original.bboxes)
    said = {(p.file, p.field): p.issue for p in lied.problems}
    assert "topic missing" in said["metadata.yaml", actors]
    assert "std_msgs/msg/String" in said["metadata.yaml", detections]
    assert "not in the storage" in said["metadata.yaml", "/ghost"]
    assert len(list(lied.problems)) == 3
    code, out, _ = verdict(bag, capsys)
    assert code == 0 and "verdict: perception" in out and "metadata.yaml: " + actors in out


def test_unreadable_metadata_yaml_falls_back_to_the_storage(
    bags: dict[str, Path], tmp_path: Path
) -> None:
    bag = tmp_path / "garbled"
    shutil.copytree(bags["zstd"], bag)
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: [unclosed\n")
    log = read_bag(bag)
    assert len(log.actors) == 81
    (p,) = list(log.problems)
    assert p.file == "metadata.yaml" and "unreadable" in p.issue


# --- a SIGKILLed recorder -----------------------------------------------------------------


def test_sigkilled_recording_is_reported_as_cut(
    ros_env: RosEnv,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    bag, ns = tmp_path / "bag", ros_env.namespace
    with Launcher(ros_env.env, echo=sys.stderr) as launcher:
        recorder = start_recorder(
            launcher, bag, ns, chunk_size=16384, flush_period_s=0.0, compression="zstd"
        )
        player = start_player(launcher, EXAMPLE, ns, loop=True)
        deadline = time.monotonic() + 60
        mcap = bag / "bag_0.mcap"
        while not (mcap.exists() and mcap.stat().st_size > 4 * 4096):
            assert time.monotonic() < deadline, recorder.output
            assert recorder.returncode is None, recorder.output
            time.sleep(0.05)
        recorder.process.send_signal(signal.SIGKILL)
        assert recorder.wait(10) == -signal.SIGKILL
        player.process.kill()
        player.wait(10)
    assert not (bag / "metadata.yaml").exists()
    assert cli(["inspect", str(bag), "--json"]) == 0
    problems = json.loads(capsys.readouterr().out)["problems"]
    cut = [p for p in problems if p["file"] == "bag_0.mcap" and "truncated after" in p["issue"]]
    assert len(cut) == 1 and cut[0]["field"] == "data section", problems
    assert cli(["inspect", str(bag)]) == 0
    assert "bag_0.mcap: data section: truncated after" in capsys.readouterr().out
    code, out, err = verdict(bag, capsys)
    assert "Traceback" not in err, err
    if code == 2:  # killed before the recorder had written the player's run/metadata message
        assert err.count("\n") == 1 and "no run/metadata message" in err, err
        assert "bag_0.mcap: data section: truncated after" in err, err
    else:
        assert code == 0 and "bag_0.mcap: data section: truncated after" in out, out


# --- storage files and metadata.yaml that are not regular files ----------------------------


def _not_regular(path: Path, kind: str) -> None:
    """Put a FIFO, or a symlink to a device, at ``path``."""
    path.unlink(missing_ok=True)
    if kind == "fifo":
        os.mkfifo(path)
    else:
        path.symlink_to(kind)


@pytest.mark.parametrize("kind", ["fifo", "/dev/zero", "/dev/urandom"])
@pytest.mark.parametrize("storage", ["zstd", "sqlite3"])
def test_a_storage_file_that_is_not_regular_is_one_line(
    bags: dict[str, Path], tmp_path: Path, kind: str, storage: str
) -> None:
    """The only storage file of a bag directory (listed in its metadata.yaml, or not), or
    a bare path: never opened (a FIFO blocked forever, /dev/zero read until memory ran
    out), one error line naming it, exit 2, from every command."""
    bag = Path(shutil.copytree(bags[storage], tmp_path / "bag"))
    listed = storage_file(bag)
    _not_regular(listed, kind)
    unlisted = tmp_path / "unlisted"  # metadata.yaml names no file there: the one present
    unlisted.mkdir()
    shutil.copy(bag / "metadata.yaml", unlisted)
    _not_regular(unlisted / f"x_0{listed.suffix}", kind)
    why = "FIFO" if kind == "fifo" else "character device"
    for path, name in (
        (bag, listed),
        (unlisted, unlisted / f"x_0{listed.suffix}"),
        (listed, listed),
    ):
        for command in ("inspect", "diagnose", "convert"):
            out = [str(tmp_path / "out")] if command == "convert" else []
            done = run_limited(command, str(path), *out)
            assert_clean(done, 2)
            assert done.stderr.count("\n") == 1, done.stderr
            assert f"{name}: not a regular file ({why})" in done.stderr, done.stderr


def test_a_fifo_beside_a_readable_storage_file_is_a_problem(
    bags: dict[str, Path], tmp_path: Path
) -> None:
    """metadata.yaml lists two files, the second a FIFO: the first is read and diagnosed,
    the FIFO named as skipped."""
    bag = Path(shutil.copytree(bags["zstd"], tmp_path / "bag"))
    path = bag / "metadata.yaml"
    document = yaml.safe_load(path.read_text())
    info = document["rosbag2_bagfile_information"]
    info["relative_file_paths"].append("bag_1.mcap")
    path.write_text(yaml.safe_dump(document))
    os.mkfifo(bag / "bag_1.mcap")
    done = run_limited("diagnose", str(bag), "--workers", "1")
    assert_clean(done)
    assert "verdict: perception" in done.stdout
    assert "bag_1.mcap: not a regular file (FIFO) (file skipped)" in done.stdout, done.stdout


@pytest.mark.parametrize("kind", ["fifo", "/dev/zero"])
def test_a_metadata_yaml_that_is_not_regular_is_a_problem(
    bags: dict[str, Path], tmp_path: Path, kind: str
) -> None:
    bag = Path(shutil.copytree(bags["zstd"], tmp_path / "bag"))
    _not_regular(bag / "metadata.yaml", kind)
    done = run_limited("inspect", "--json", str(bag))
    assert_clean(done)
    why = "FIFO" if kind == "fifo" else "character device"
    problems = json.loads(done.stdout)["problems"]
    assert any(
        p["file"] == "metadata.yaml" and p["issue"] == f"unreadable: not a regular file ({why})"
        for p in problems
    ), problems
