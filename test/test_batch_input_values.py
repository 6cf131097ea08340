"""Values a user types that ``ads-rca batch`` misread (issue 43, item 6c).

Real files and real subprocesses of ``python -m ads_rca.cli``. Checked: a paths file that
starts with a UTF-8 byte order mark (as Notepad saves it) finds its first path.
"""

from __future__ import annotations

from pathlib import Path

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
