"""Values a user types that ``ads-rca batch`` misread (issue 43, items 6c and 6e).

Real files and real subprocesses of ``python -m ads_rca.cli``. Checked: a paths file that
starts with a UTF-8 byte order mark (as Notepad saves it) finds its first path; every
hostile ``--timeout`` (``--timeout=--``, nan, -1, inf, empty, 1e999...) is one line, exit
status 2, naming the option and the value, never a traceback (``--timeout=--`` was a
TypeError); any ``--option=--`` of any command is one line too (argparse gave it an empty
list whatever the option's type).
"""

from __future__ import annotations

from pathlib import Path

import pytest
from commandline import assert_one_line, run_cli

from ads_rca.batch.inputs import expand_inputs, read_paths_file


def test_a_paths_file_with_a_byte_order_mark_finds_its_first_path(tmp_path: Path) -> None:
    for name in ("run_a", "run_b"):
        (tmp_path / name).mkdir()
    listed = tmp_path / "runs.txt"
    listed.write_bytes("\ufeffrun_a\nrun_b\n".encode())
    assert read_paths_file(str(listed)) == [str(tmp_path / "run_a"), str(tmp_path / "run_b")]
    assert [run.path for run in expand_inputs([str(listed)])] == [
        str((tmp_path / name).resolve()) for name in ("run_a", "run_b")
    ]


def test_a_byte_order_mark_inside_a_line_is_still_no_path(tmp_path: Path) -> None:
    """Only the file's first character is an editor's mark; elsewhere it is the path's."""
    (tmp_path / "run_a").mkdir()
    listed = tmp_path / "runs.txt"
    listed.write_bytes("run_a\n\ufeffrun_a\n".encode())
    done = run_cli("batch", str(listed), "--out", str(tmp_path / "out"))
    assert_one_line(done, f"{listed}:2: ")


@pytest.mark.parametrize(
    "value", ["--", "nan", "NaN", "-1", "0", "inf", "-inf", "", " ", "1e999", "1e7", "0x10", "ten"]
)
def test_a_hostile_timeout_is_one_line(tmp_path: Path, value: str) -> None:
    (tmp_path / "run").mkdir()
    done = run_cli("batch", str(tmp_path / "run"), f"--timeout={value}", "--out",
                   str(tmp_path / "out"))  # fmt: skip
    assert_one_line(done, "--timeout")
    assert "seconds" in done.stderr or "'--' is no value of --timeout" in done.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    ("command", "option"),
    [("batch", "--retries"), ("batch", "--workers"), ("watch", "--timeout"),
     ("diagnose", "--event-time"), ("replay", "--timeout")],
)  # fmt: skip
def test_any_option_given_dash_dash_is_one_line(tmp_path: Path, command: str, option: str) -> None:
    (tmp_path / "run").mkdir()
    args = [] if command == "watch" else [str(tmp_path / "run")]
    done = run_cli(command, *args, f"{option}=--", timeout=60)
    assert_one_line(done, f"ads-rca {command}: error: {option}=--: '--' is no value of {option}")
