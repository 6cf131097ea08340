"""Parameters on the command line and in ``--config`` files: ranges, unknown names, what each
does in each mode, and the effective window named by every output.

Out-of-range values (``safety_margin=-1``, ``nan``, ``window_s=-3``) used to be accepted and
change the verdict; a misspelt ``--config`` key was silently ignored; and
``-p effect_time_window=15`` (the help's own example) changes nothing in ``corrected`` mode,
where the window is ``max(effect_time_window, round(window_s / frame period))``.
"""

from __future__ import annotations

import subprocess
from dataclasses import fields
from pathlib import Path
from typing import Any

import pytest
from commandline import run_cli

from ads_rca.diagnosis.engine import diagnose
from ads_rca.diagnosis.summary import summary_text
from ads_rca.oracles.semantics import semantics_for
from ads_rca.params import SEMANTICS, Params, make_params, parameters_markdown
from ads_rca.paramspec import SPECS
from ads_rca.report.html import write_report
from ads_rca.sources.log.reader import read_run_log

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "examples" / "cut_in_perception"


def refused(done: subprocess.CompletedProcess[str]) -> str:
    """The one error line of a refused command (exit 2, no traceback)."""
    assert done.returncode == 2, done.stdout + done.stderr
    assert "Traceback" not in done.stderr
    assert done.stderr.count("\n") == 1, done.stderr
    return done.stderr.strip()


# --- ranges ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("assignment", "message"),
    [
        ("safety_margin=-1", "parameter safety_margin: -1 is out of range [0, 100] m"),
        ("safety_margin=nan", "parameter safety_margin: nan is out of range [0, 100] m"),
        ("window_s=-3", "parameter window_s: -3 is out of range [0, 3600] s"),
        ("window_s=inf", "parameter window_s: inf is out of range [0, 3600] s"),
        (
            "effect_time_window=-1",
            "parameter effect_time_window: -1 is out of range [0, 100000] frames",
        ),
        ("perc_match_iou=1.5", "parameter perc_match_iou: 1.5 is out of range [0, 1]"),
        ("max_decel=0", "parameter max_decel: 0 is out of range [0.1, 100] m/s²"),
        ("min_persistence=0", "parameter min_persistence: 0 is out of range [1, 1000] frames"),
        ("max_file_mb=-5", "parameter max_file_mb: -5 is out of range [0.001, 1048576] MB"),
        ("noise_floor_s=1e9", "parameter noise_floor_s: 1000000000 is out of range [0, 60] s"),
        ("noise_floor_factor=nan", "parameter noise_floor_factor: nan is out of range [0, 100]"),
        (
            "noise_floor_min_frames=0",
            "parameter noise_floor_min_frames: 0 is out of range [1, 100000] frames",
        ),
    ],
)
def test_a_value_out_of_range_on_the_command_line_is_refused_naming_the_range(
    assignment: str, message: str
) -> None:
    line = refused(run_cli("diagnose", str(EXAMPLE), "-p", assignment))
    assert line == f"ads-rca diagnose: error: {message}"


def test_a_value_out_of_range_in_a_config_file_is_refused_naming_the_file(tmp_path: Path) -> None:
    config = tmp_path / "rca.yaml"
    config.write_text("/**:\n  ros__parameters:\n    safety_margin: -1.0\n")
    line = refused(run_cli("diagnose", str(EXAMPLE), "--config", str(config)))
    assert line == (
        f"ads-rca diagnose: error: {config}: parameter safety_margin: -1 is out of range [0, 100] m"
    )


def test_max_file_mb_and_rate_flags_are_range_checked_too(tmp_path: Path) -> None:
    line = refused(run_cli("diagnose", str(EXAMPLE), "--max-file-mb", "nan"))
    assert line.endswith("parameter max_file_mb: nan is out of range [0.001, 1048576] MB")
    line = refused(run_cli("replay", str(EXAMPLE), "--rate", "-1"))
    assert line.endswith("parameter --rate: -1 is out of range [0, 1000]")
    for command in ("replay", "demo"):  # a negative or NaN timeout waited not at all
        for value in ("-1", "nan", "0", "1e9"):
            line = refused(run_cli(command, str(EXAMPLE), "--timeout", value))
            shown = {"1e9": "1000000000"}.get(value, value)
            assert line.endswith(f"parameter --timeout: {shown} is out of range [0.001, 604800] s")


def test_every_threshold_has_a_range_holding_both_modes_defaults() -> None:
    names = [f.name for f in fields(Params) if f.name != "semantics"]
    assert list(SPECS) == names
    for f in fields(Params):
        if f.name != "semantics":
            assert SPECS[f.name].range.integer == (f.type == "int"), f.name
    for mode in SEMANTICS:
        params = make_params(mode)
        for name, spec in SPECS.items():
            spec.range.check(name, getattr(params, name))  # raises when out of range


def test_each_parameter_says_what_it_does_exactly_in_the_modes_that_read_it() -> None:
    for mode in SEMANTICS:
        read = set(semantics_for(mode).parameters)
        described = {name for name, spec in SPECS.items() if mode in spec.effect}
        assert described == read, mode


def test_docs_hold_the_parameter_table_and_help_lists_every_parameter() -> None:
    assert parameters_markdown() in (ROOT / "docs" / "parameters.md").read_text()
    help_text = run_cli("diagnose", "--help").stdout
    for name in SPECS:
        assert f"  {name}: default " in help_text
    assert "max(effect_time_window, round(window_s /" in help_text


# --- unknown names ----------------------------------------------------------------------


def test_an_unknown_key_in_a_config_file_is_refused_with_the_known_names(tmp_path: Path) -> None:
    config = tmp_path / "rca.yaml"
    config.write_text("safety_margn: 0.8\nlog_path: a-node-parameter-is-known\n")
    line = refused(run_cli("diagnose", str(EXAMPLE), "--config", str(config)))
    assert line.startswith(f"ads-rca diagnose: error: {config}: unknown parameter 'safety_margn'")
    known = line.split("(known: ", 1)[1].rstrip(")").split(", ")
    assert {"safety_margin", "window_s", "semantics", "max_file_mb", "log_path"} <= set(known)


def test_an_unknown_p_name_is_refused_with_the_known_names() -> None:
    line = refused(run_cli("diagnose", str(EXAMPLE), "-p", "safety_margn=0.8"))
    assert "unknown parameter 'safety_margn' (known: " in line
    assert "safety_margin" in line


# --- the effective window -----------------------------------------------------------------


@pytest.fixture(scope="module")
def example_log() -> Any:
    return read_run_log(EXAMPLE)


def window_of(log: Any, semantics: str, **overrides: Any) -> dict[str, Any]:
    document = diagnose(log, make_params(semantics, overrides)).to_json()
    return dict(document["effect_window"], window_frames=document["window_frames"])


def test_corrected_window_is_the_larger_of_its_two_parameters(example_log: Any) -> None:
    # The example runs at 50 ms a frame: window_s 1 s is 20 frames.
    assert window_of(example_log, "corrected") == {
        "frames": 20,
        "ms": 1000,
        "set_by": ["effect_time_window", "window_s"],
        "rule": "max(effect_time_window 20, round(window_s 1 s / 50 ms) 20)",
        "counts": "frames collision_frame - 20 to collision_frame",
        "window_frames": 20,
    }
    below = window_of(example_log, "corrected", effect_time_window=15)
    assert (below["frames"], below["set_by"]) == (20, ["window_s"])
    above = window_of(example_log, "corrected", effect_time_window=30)
    assert (above["frames"], above["set_by"]) == (30, ["effect_time_window"])
    assert above["rule"] == "max(effect_time_window 30, round(window_s 1 s / 50 ms) 20)"


def test_effect_time_window_below_window_s_changes_nothing_in_corrected(example_log: Any) -> None:
    """What the docs say: in corrected mode effect_time_window is only a lower bound."""
    default = diagnose(example_log, make_params("corrected")).to_json()
    lowered = diagnose(example_log, make_params("corrected", {"effect_time_window": 15})).to_json()
    assert lowered["modules"] == default["modules"]
    assert lowered["thresholds"]["effect_time_window"] == 15


def test_reference_window_is_effect_time_window_with_no_upper_bound(example_log: Any) -> None:
    assert window_of(example_log, "reference", effect_time_window=15) == {
        "frames": 15,
        "ms": 750,
        "set_by": ["effect_time_window"],
        "rule": "effect_time_window 15",
        "counts": "frames after collision_frame - 15, with no upper bound",
        "window_frames": 15,
    }


def test_summary_report_and_verdict_status_name_the_effective_window(
    example_log: Any, tmp_path: Path
) -> None:
    from ads_rca.live.diagnostics import verdict_status

    result = diagnose(example_log, make_params("corrected", {"window_s": 2.0}))
    line = (
        "effect window: 40 frames (2000 ms) = max(effect_time_window 20, round(window_s 2 s "
        "/ 50 ms) 40); counts frames collision_frame - 40 to collision_frame"
    )
    document = result.to_json()
    assert line in summary_text(document).splitlines()
    write_report(result, tmp_path / "report.html")
    assert line in (tmp_path / "report.html").read_text()
    values = dict(verdict_status(document, "ads_rca").values)
    assert values["effect_window.frames"] == "40"
    assert values["effect_window.set_by"] == '["window_s"]'
    assert values["effect_window.rule"] == (
        "max(effect_time_window 20, round(window_s 2 s / 50 ms) 40)"
    )
