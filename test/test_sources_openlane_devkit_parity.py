"""Our OpenLane-V2 figures equal the official devkit's on data shaped like the released files.

The devkit (openlanev2 2.1.0, in its own venv) scored each case of
test/writers/openlane_released.py once; bench/bench_openlane_devkit.py ``--pin`` stored its
figures in test/golden/openlane_devkit_2_1_0.json. Here each case's data are written again
by the same generator (no devkit needed) and scored as users score them: the split through
the reader and ``score_frames(..., devkit_empty=True)``, and one case per segment through
``python -m ads_rca.cli diagnose --json``. Every figure must be within the pinned tolerance
(1e-6: the devkit works in float32).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest
from writers.openlane_released import (
    CASES,
    FIGURES,
    POINT_INTERVAL,
    SEGMENTS,
    SPLIT,
    cli_scores,
    parameters,
    scored_pairs,
    write_released_split,
)

from ads_rca.sources.openlane.scores import score_frames

GOLDEN = Path(__file__).resolve().parent / "golden" / "openlane_devkit_2_1_0.json"
#: The case also run through the command line, segment by segment.
CLI_CASE = "baseline_noisy"


@pytest.fixture(scope="module")
def pinned() -> dict[str, Any]:
    found: dict[str, Any] = json.loads(GOLDEN.read_text(encoding="utf-8"))
    return found


def far(expected: dict[str, float], found: dict[str, Any], tolerance: float) -> dict[str, Any]:
    """The figures of ``found`` not within ``tolerance`` of ``expected``: name -> (devkit,
    ours)."""
    off = {}
    for key in FIGURES:
        value = found.get(key)
        if (
            isinstance(value, bool)
            or not isinstance(value, float | int)
            or not math.isclose(value, expected[key], abs_tol=tolerance)
        ):
            off[key] = (expected[key], value)
    return off


def test_the_pins_say_where_they_come_from(pinned: dict[str, Any]) -> None:
    assert pinned["devkit"] == {"package": "openlanev2", "version": "2.1.0"}
    assert pinned["numpy"].startswith("1.23.")  # the devkit's numpy < 1.24
    assert pinned["environment"]["numpy"] == pinned["numpy"]
    assert pinned["split_rule"]["split"] == SPLIT == "val"
    assert pinned["split_rule"]["point_interval"] == POINT_INTERVAL == 20
    assert pinned["tolerance"] == 1e-6
    # the data here are the data the devkit scored
    assert pinned["generator"] == json.loads(json.dumps(parameters()))
    assert set(pinned["cases"]) == set(CASES)


@pytest.mark.parametrize("case", list(CASES))
def test_the_split_scores_as_the_devkit_does(
    case: str, tmp_path: Path, pinned: dict[str, Any]
) -> None:
    write_released_split(tmp_path, CASES[case])
    pairs = scored_pairs(tmp_path)
    assert len(pairs) == pinned["generator"]["frames_per_segment"] * len(SEGMENTS)
    ours = score_frames(pairs, devkit_empty=True).to_dict()
    assert far(pinned["cases"][case]["split"], ours, pinned["tolerance"]) == {}


def test_diagnose_reports_each_segment_as_the_devkit_scores_it(
    tmp_path: Path, pinned: dict[str, Any]
) -> None:
    write_released_split(tmp_path, CASES[CLI_CASE])
    expected = pinned["cases"][CLI_CASE]["segments"]
    off = {}
    for segment in SEGMENTS:
        found = cli_scores(tmp_path, segment, tmp_path / f"{segment.name}.json")
        assert found.get("frames") == pinned["generator"]["frames_per_segment"]
        gaps = far(expected[segment.name], found, pinned["tolerance"])
        if gaps:
            off[segment.name] = gaps
    assert off == {}
