"""The YAML files a user names (``--config``, ``--remap``, ``--profile FILE``) when they are
not what they claim: one line naming the file, exit 2, at once.

Before: text that is not UTF-8 and YAML nested deeper than the parser recurses ended
``diagnose --config`` with a traceback; a FIFO or ``/dev/zero`` named by mistake hung it
(or filled memory); and a "billion laughs" document (aliases sharing one list nine times at
each of nine levels: 600 bytes of YAML) hung every command whose error message showed the
value, since its repr is 9**9 items long. Every case runs through the real command line.
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest
from commandline import run_cli

from ads_rca.errors import ConfigError
from ads_rca.foundation.text import short_repr
from ads_rca.sources.bag.profiles.profile import load_profile

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "cut_in_perception"
#: A billion-laughs value: nine levels of nine aliases of the level below.
BOMB = (
    "["
    + ", ".join(
        ["&a0 [1, 1, 1, 1, 1, 1, 1, 1, 1]"]
        + [f"&a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 9)]
    )
    + "]"
)

#: The YAML bomb and the FIFO used to hang for ever: a run past this fails the test.
HANG = 60


ACTORS = "{topic: /objects, type: derived_object_msgs/msg/ObjectArray}"
GOOD_PROFILE = f"profile: mine\ninputs:\n  actors: {ACTORS}\n"


def hostile_files(folder: Path) -> dict[str, tuple[Path, str]]:
    """Name → (file, what the one error line must say)."""
    made: dict[str, tuple[Path, str]] = {}

    def write(name: str, data: bytes | str, said: str) -> None:
        path = folder / f"{name}.yaml"
        path.write_bytes(data if isinstance(data, bytes) else data.encode())
        made[name] = (path, said)

    write("not_utf8", b"semantics: reference\nmin_iou: \xff\xfe\n", "codec can't decode")
    write("deep_list", "min_iou: " + "[" * 50_000 + "]" * 50_000 + "\n", "nested too deep")
    write("deep_map", "min_iou: " + "{a: " * 20_000 + "1" + "}" * 20_000 + "\n", "nested too deep")
    write("too_large", "# " + "x" * (2 << 20) + "\n", "larger than 1 MB")
    write("bomb_value", f"safety_margin: {BOMB}\n", "is not a number")
    write("bomb_semantics", f"semantics: {BOMB}\n", "semantics must be one of")
    write("huge_integer", "ego_agent: 1" + "0" * 5000 + "\n", "integer string conversion")
    write("impossible_date", "semantics: 2001-13-40\n", "month must be in 1..12")
    fifo = folder / "fifo.yaml"
    os.mkfifo(fifo)
    made["fifo"] = (fifo, "not a regular file (FIFO)")
    zero = folder / "zero.yaml"
    zero.symlink_to("/dev/zero")
    made["dev_zero"] = (zero, "not a regular file (character device)")
    made["directory"] = (folder, "not a regular file (a directory)")
    made["missing"] = (folder / "missing.yaml", "no such file")
    return made


def one_error_line(done: subprocess.CompletedProcess[str], file: Path, said: str) -> None:
    assert done.returncode == 2, done.stdout + done.stderr
    assert "Traceback" not in done.stderr, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and str(file) in lines[0] and said in lines[0], lines
    assert len(lines[0]) < 600, lines[0]


CASES = [
    "not_utf8",
    "deep_list",
    "deep_map",
    "too_large",
    "bomb_value",
    "bomb_semantics",
    "huge_integer",
    "impossible_date",
    "fifo",
    "dev_zero",
    "directory",
    "missing",
]


@pytest.mark.parametrize("case", CASES)
@pytest.mark.parametrize("command", ["diagnose", "batch"])
def test_a_hostile_config_file_is_one_line_and_exit_2(
    tmp_path: Path, case: str, command: str
) -> None:
    file, said = hostile_files(tmp_path)[case]
    extra = ["--out", str(tmp_path / "out")] if command == "batch" else []
    one_error_line(
        run_cli(command, str(EXAMPLE), "--config", str(file), *extra, timeout=HANG), file, said
    )


@pytest.mark.parametrize("case", ["not_utf8", "deep_list", "fifo", "dev_zero", "missing"])
def test_a_hostile_remap_file_is_one_line_and_exit_2(tmp_path: Path, case: str) -> None:
    file, said = hostile_files(tmp_path)[case]
    one_error_line(
        run_cli("diagnose", str(EXAMPLE), "--remap", str(file), timeout=HANG), file, said
    )


@pytest.mark.parametrize("case", ["not_utf8", "deep_list", "deep_map", "fifo", "dev_zero"])
def test_a_hostile_profile_file_is_one_config_error(tmp_path: Path, case: str) -> None:
    """Profiles read bags only (a bag is built in test_sources_bag_stack_recordings); the
    loader is the same for every command."""
    file, said = hostile_files(tmp_path)[case]
    with pytest.raises(ConfigError) as caught:
        load_profile(file)
    assert "\n" not in str(caught.value) and said in str(caught.value)


def test_a_billion_laughs_in_a_remap_is_one_line(tmp_path: Path) -> None:
    for text, said in (
        (f"/their/topic: {BOMB}\n", "is not a contract topic key"),
        (f"? {BOMB}\n: actors\n", "not a YAML remapping file"),
    ):
        file = tmp_path / "bomb.yaml"
        file.write_text(text)
        one_error_line(
            run_cli("diagnose", str(EXAMPLE), "--remap", str(file), timeout=HANG), file, said
        )


@pytest.mark.timeout(30)
@pytest.mark.parametrize(
    ("text", "said"),
    [
        (f"profile: {BOMB}\ninputs: {{}}\n", "is not a string"),
        (GOOD_PROFILE + f"metadata: {{camera_loc: {BOMB}}}\n", "is not [x, y, z]"),
        (f"profile: p\ncontract: {BOMB}\n", "is not true or false"),
    ],
)
def test_a_billion_laughs_in_a_profile_is_one_line(tmp_path: Path, text: str, said: str) -> None:
    file = tmp_path / "bomb.yaml"
    file.write_text(text)
    with pytest.raises(ConfigError) as caught:
        load_profile(file)
    assert said in str(caught.value) and len(str(caught.value)) < 300


def test_short_repr_never_walks_the_whole_value() -> None:
    import yaml

    bomb = yaml.safe_load(f"v: {BOMB}")["v"]
    assert len(short_repr(bomb)) <= 40 and short_repr(bomb).startswith("[[")
    assert short_repr("abc") == "'abc'" and short_repr(2.5) == "2.5"
    assert "..." in short_repr("x" * 1000, 60) and len(short_repr("x" * 1000, 60)) <= 60
