"""What the command line shows: a progress bar on a terminal only, quiet ends in a pipe,
real values from ``synth``, and help that names what a path may be.

Real processes: the ``ads-rca`` console script with its stderr on a pseudo-terminal (the
``pty`` module) or on a pipe, and in a shell pipeline with ``head``.
"""

from __future__ import annotations

import argparse
import fcntl
import os
import pty
import struct
import subprocess
import sys
import termios
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from ads_rca.cli import EXIT_BROKEN_PIPE, build_parser
from ads_rca.commands.progress_bar import MIN_ITEMS
from ads_rca.commands.synth_cmd import describe
from ads_rca.model import ALL_FOLDERS
from ads_rca.synth import synthesise_run

if TYPE_CHECKING:
    from conftest import RosEnv

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "examples" / "cut_in_perception"
ADS_RCA = str(Path(sys.executable).with_name("ads-rca"))
#: A log long enough for both bars: 10 folders × 310 files, 310 frames.
LONG_FRAMES = 310


@pytest.fixture(scope="module")
def long_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("long") / "cruise"
    argv = ["synth", str(folder), "--scenario", "cruise", "--seed", "1", "--actors", "1"]
    subprocess.run([ADS_RCA, *argv, "--frames", str(LONG_FRAMES)], check=True, capture_output=True)
    files = sum(1 for f in folder.rglob("*.json") if f.parent != folder)
    assert files >= MIN_ITEMS["loading"] and MIN_ITEMS["judging"] <= LONG_FRAMES
    return folder


def run_on_pty(argv: list[str]) -> tuple[int, bytes, bytes]:
    """Exit status, stdout (a pipe) and everything written to stderr (a terminal)."""
    controller, terminal = pty.openpty()
    # 24 × 80, as a terminal window has (a new pty is 0 × 0: no room for a bar).
    fcntl.ioctl(terminal, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 80, 0, 0))
    process = subprocess.Popen(
        argv, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=terminal
    )
    os.close(terminal)
    seen = bytearray()
    while True:
        try:
            chunk = os.read(controller, 65536)
        except OSError:  # EIO: the process closed its end of the terminal
            break
        if not chunk:
            break
        seen += chunk
    os.close(controller)
    assert process.stdout is not None
    out = process.stdout.read()
    process.stdout.close()
    return process.wait(), out, bytes(seen)


def test_diagnose_shows_a_loading_and_judging_bar_on_a_terminal(long_log: Path) -> None:
    status, out, terminal = run_on_pty([ADS_RCA, "diagnose", str(long_log), "--workers", "1"])
    assert status == 0
    # Both bars, each with its total: every folder's files read, then the frames judged.
    # A synthesised run holds 3-D objects and controls, no lane graphs.
    files = len([f for f in ALL_FOLDERS if not f.startswith("lanes")]) * LONG_FRAMES
    assert b"\rloading: " in terminal and f"/{files} [".encode() in terminal
    assert b"\rjudging: " in terminal and f"/{LONG_FRAMES} [".encode() in terminal
    assert out.startswith(f"{long_log}: {LONG_FRAMES} frames judged".encode())
    assert b"loading" not in out and b"judging" not in out
    status, out, terminal = run_on_pty([ADS_RCA, "inspect", str(long_log)])
    assert status == 0 and b"\rloading: " in terminal and b"judging" not in terminal


def test_diagnose_shows_no_bar_on_a_pipe(long_log: Path) -> None:
    result = subprocess.run(
        [ADS_RCA, "diagnose", str(long_log), "--workers", "1"], capture_output=True, check=True
    )
    assert result.stderr == b""
    assert result.stdout.startswith(f"{long_log}: {LONG_FRAMES} frames judged".encode())


def test_head_ends_the_output_quietly() -> None:
    result = subprocess.run(
        ["sh", "-c", f'"{ADS_RCA}" diagnose "{EXAMPLE}" --semantics both | head -1'],
        capture_output=True,
        text=True,
        check=True,
    )
    assert result.stdout == f"{EXAMPLE}: 81 frames judged, semantics reference\n"
    assert result.stderr == ""


def test_a_closed_pipe_is_exit_status_141_with_nothing_on_stderr(tmp_path: Path) -> None:
    """The reader gone before the first write: every write fails, deterministically."""
    read_end, write_end = os.pipe()
    os.close(read_end)
    out = tmp_path / "verdict.json"
    argv = [ADS_RCA, "diagnose", str(EXAMPLE), "--json", str(out)]
    try:
        result = subprocess.run(
            argv, stdout=write_end, stderr=subprocess.PIPE, text=True, check=False
        )
    finally:
        os.close(write_end)
    assert (result.returncode, result.stderr) == (EXIT_BROKEN_PIPE, "")
    assert EXIT_BROKEN_PIPE == 141
    assert out.read_text().startswith("{")  # the files never depend on stdout


def test_synth_prints_what_happened(tmp_path: Path) -> None:
    argv = [ADS_RCA, "synth", str(tmp_path / "c"), "--scenario", "cruise", "--frames", "40"]
    result = subprocess.run([*argv, "--actors", "1"], capture_output=True, text=True, check=True)
    assert result.stdout == (
        f"{tmp_path / 'c'}: cruise/none seed 0: 40 frames, no collision, no partner, "
        "no fault injected\n"
    )
    _, crash = synthesise_run("lead_braking", "control", 0)
    assert describe(crash) == (
        f"lead_braking/controller seed 0: {crash['total_frames']} frames, collision at frame "
        f"{crash['collision_frame']} with actor {crash['partner_id']} (the partner), "
        f"controller fault from frame {crash['fault_onset_frame']}"
    )
    assert crash["collision_frame"] >= 0 and crash["fault_onset_frame"] >= 0
    _, twin = synthesise_run("lead_braking", "none", 0)
    assert describe(twin) == (
        f"lead_braking/none seed 0: {twin['total_frames']} frames, no collision "
        f"(partner actor {twin['partner_id']} avoided), no fault injected"
    )


@pytest.mark.parametrize(
    ("command", "dest"),
    [
        ("diagnose", "path"),
        ("inspect", "path"),
        ("replay", "path"),
        ("demo", "log_dir"),
        ("convert", "source"),
    ],
)
def test_help_says_log_folder_or_bag_where_both_are_read(command: str, dest: str) -> None:
    subparsers = next(
        a for a in build_parser(command)._actions if isinstance(a, argparse._SubParsersAction)
    )
    parser = subparsers.choices[command]
    action = next(a for a in parser._actions if a.dest == dest)
    assert action.help == "log folder or bag"


def test_demo_piped_to_head_ends_quietly_and_its_nodes_with_it(
    ros_env: RosEnv, tmp_path: Path
) -> None:
    """The echo of the nodes' lines meets the closed pipe in a reader thread: it stops
    echoing (no thread traceback) and keeps draining the nodes, and the command ends."""
    script = (
        f'"{ADS_RCA}" demo "{EXAMPLE}" --domain-id {ros_env.domain_id} '
        f'--out "{tmp_path / "out"}" | head -1'
    )
    result = subprocess.run(
        ["sh", "-c", script],
        env=ros_env.env,
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
    )
    assert result.stdout.startswith(f"ads-rca demo: ROS_DOMAIN_ID={ros_env.domain_id} ")
    assert result.stdout.count("\n") == 1
    assert result.stderr == ""


@pytest.mark.parametrize(
    ("argv", "status", "expected"),
    [
        (["nosuch"], 2, "invalid choice: 'nosuch'"),
        ([""], 2, "invalid choice: ''"),
        (["diagnose"], 2, "the following arguments are required: path"),
        (["--bogus"], 2, "the following arguments are required: COMMAND"),
        (["diagnose\x1b[31m"], 2, "invalid choice"),
        (["--version"], 0, "ads-rca 0."),
        (["convert", "--help"], 0, "usage: ads-rca convert"),
    ],
)
def test_the_first_word_picks_the_command_whatever_it_is(
    argv: list[str], status: int, expected: str
) -> None:
    """Only the named command's module is loaded: any other first word gets the full
    parser's answer (every command listed), never a traceback."""
    done = subprocess.run(
        [sys.executable, "-m", "ads_rca.cli", *argv], capture_output=True, text=True, check=False
    )
    assert done.returncode == status, done.stderr
    assert expected in done.stdout + done.stderr
    assert "Traceback" not in done.stderr
    if status == 2 and argv != ["diagnose"]:
        assert "choose from" in done.stderr or "COMMAND" in done.stderr
