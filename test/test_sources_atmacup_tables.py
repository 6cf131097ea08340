"""atmaCup #18 tables: every field of the synthesised rows
(test/writers/atmacup_tables.py) as worked out by hand, the mirrored paths, traffic lights
(empty and not), the capability record, a submission's scores computed by hand (order- and
ID-matched), hostile tables, traffic-light files and submissions, format detection, and
``ads-rca diagnose`` printing the scores.
"""

from __future__ import annotations

import json
import math
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pytest
from commandline import run_script
from writers.atmacup_tables import (
    LIGHTS,
    ROWS,
    SCENE_A,
    TARGETS,
    TEST,
    TRAIN,
    Path3,
    write_submission,
    write_table,
)

from ads_rca.contract import topics
from ads_rca.contract.ego_paths import (
    ego_path_document,
    merged,
    read_ego_path,
    snapshots_from_rows,
)
from ads_rca.contract.errors import MalformedMessage
from ads_rca.contract.jsontext import dumps_json, loads_json
from ads_rca.diagnosis.engine import diagnose
from ads_rca.errors import InputError
from ads_rca.model import RunLog
from ads_rca.params import make_params
from ads_rca.ros.launcher import ManagedProcess
from ads_rca.sources.atmacup.reader import read_atmacup_table
from ads_rca.sources.atmacup.trajectory_scores import TRAJECTORY_SCORES_KEY, trajectory_scores
from ads_rca.sources.formats import SourceOptions
from ads_rca.sources.registry import detect_format, open_run

if TYPE_CHECKING:
    from conftest import RosEnv

ADS_RCA = str(Path(sys.executable).with_name("ads-rca"))
IDS = [row.ident for row in ROWS]


def problems_of(log: RunLog) -> list[str]:
    return [f"{p.file} {p.field}: {p.issue} ({p.action})" for p in log.problems]


def read(folder: Path, submission: Path | None = None) -> RunLog:
    source = SourceOptions(submission=str(submission) if submission else "")
    return read_atmacup_table(folder, source=source)


def scores_of(log: RunLog) -> dict[str, Any]:
    assert log.ego_snapshots is not None
    return trajectory_scores(log.ego_snapshots)


#: The submission whose scores are worked out by hand below (the table's frame):
#: row 0: x 1 m too far at every horizon; row 1: z 0.3 m too high everywhere;
#: row 2: y 0.4 m (left) everywhere, and x 3 m short of the truth at 3.0 s.
def hand_paths() -> list[Path3]:
    row0 = tuple((x + 1.0, y, z) for x, y, z in ROWS[0].path)
    row1 = tuple((x, y, z + 0.3) for x, y, z in ROWS[1].path)
    row2 = tuple(
        (x + (3.0 if n == 5 else 0.0), 0.4, z) for n, (x, _y, z) in enumerate(ROWS[2].path)
    )
    return [row0, row1, row2]


# Hand arithmetic: |errors| summed: row 0 six x errors of 1 = 6; row 1 six z errors of 0.3
# = 1.8; row 2 six y errors of 0.4 = 2.4 plus one x error of 3 = 5.4. Total 13.2 over
# 3 rows x 18 values = 54: MAE = 13.2 / 54 = 0.24444...
HAND_MAE = 13.2 / 54
# 3-D distances: row 0 1 m at every horizon; row 1 0.3 m; row 2 0.4 m at 0.5 ... 2.5 s and
# sqrt(3^2 + 0.4^2) = sqrt(9.16) m at 3.0 s.
ROW2_FDE = math.sqrt(9.16)
HAND_ADE = [1.0, 0.3, (5 * 0.4 + ROW2_FDE) / 6]  # row 2: 0.83776
HAND_FDE = [1.0, 0.3, ROW2_FDE]


@pytest.fixture
def table(tmp_path: Path) -> Path:
    write_table(tmp_path / "data")
    return tmp_path / "data"


# --- the mapping -------------------------------------------------------------------------------


def test_every_field_maps_as_worked_out_by_hand(table: Path) -> None:
    log = read(table)
    assert problems_of(log) == []
    assert log.frames == (0, 100, 200)  # one frame per row, 100 ms apart
    assert log.frame_ms == 100 and log.metadata.collision_frame == -1
    raw = log.metadata.raw
    assert raw["snapshots"] is True and "not a time series" in raw["frame_layout"]
    assert "y' = -y" in raw["source_frame"]
    assert raw["table"] == {
        "file": TRAIN,
        "data_rows": 3,
        "rows": 3,
        "scenes": 2,
        "realised_paths": 3,
        "traffic_light_files": 3,
    }
    # The ego at the origin of each row's own frame, at its vEgo.
    assert [(p.x, p.y, p.z, p.yaw, p.speed) for p in log.pose.values()] == [
        (0.0, 0.0, 0.0, 0.0, 10.0),
        (0.0, 0.0, 0.0, 0.0, 0.0),
        (0.0, 0.0, 0.0, 0.0, 2.5),
    ]
    assert all(a.ids == ("ego",) for a in log.actors.values())
    snap = log.ego_snapshots
    assert snap is not None and snap.ids == tuple(IDS)
    assert snap.timestamps.tolist() == [0, 100, 200] and snap.file_rows.tolist() == [0, 1, 2]
    # Row 0's path: x = 5 n, y = +0.1 n LEFT in the table -> -0.1 n in the model, z = 0.01 n.
    n = np.arange(1, 7, dtype=float)
    np.testing.assert_allclose(snap.realised[0], np.stack([5 * n, -0.1 * n, 0.01 * n], axis=1))
    assert (snap.realised[1] == 0).all() and not np.signbit(snap.realised[1]).any()  # no -0.0
    np.testing.assert_allclose(snap.realised[2][:, 0], -1.25 * n)
    assert np.isnan(snap.predicted).all() and not snap.submission
    expected = {
        "vEgo": [10.0, 0.0, 2.5],
        "aEgo": [0.5, 0.0, -0.1],
        "steeringAngleDeg": [5.0, 0.0, -30.0],  # the table's sign (CCW +), not mirrored
        "steeringTorque": [-0.2, 0.0, 1.5],
        "brake": [0.0, 0.0, 0.4],
        "brakePressed": [0.0, 0.0, 1.0],
        "gas": [0.3, 0.0, 0.0],
        "gasPressed": [1.0, 0.0, 0.0],
        "leftBlinker": [1.0, 0.0, 0.0],
        "rightBlinker": [0.0, 0.0, 1.0],
    }
    assert {k: v.tolist() for k, v in snap.vehicle.items()} == expected
    assert snap.gear == ("drive", "park", "reverse")
    # Traffic lights: ids = index, label = class, pixel corners as written (not mirrored).
    first = log.bboxes[0]
    assert first.ids == ("1", "2")
    assert first.corners.tolist() == [[52.0, 0.5, 55.0, 2.5], [26.5, 1.5, 29.5, 3.5]]
    assert [e["label"] for e in first.extras] == ["green", "red"]
    assert len(log.bboxes[100]) == 0  # an empty list: a frame that saw no light
    assert log.bboxes[200].ids == ("1",) and log.bboxes[200].extras[0]["label"] == "left"


def test_capability_record_says_what_a_table_holds(table: Path) -> None:
    states = {k: v.state for k, v in read(table).inputs.items()}
    assert states == {
        "ego": "real",
        "actors": "derived",  # the ego alone
        "detections_2d": "real",
        "ground_truth_2d": "absent",
        "detections_3d": "absent",
        "tracked_objects": "absent",
        "predictions": "absent",
        "predictions_gt": "absent",
        "plan": "absent",
        "control": "absent",
        "collision": "absent",
        "clock": "absent",
    }
    (table / LIGHTS / f"{IDS[0]}.json").unlink()
    for name in os.listdir(table / LIGHTS):
        (table / LIGHTS / name).unlink()
    (table / LIGHTS).rmdir()
    log = read(table)
    assert log.inputs["detections_2d"].state == "absent" and log.bboxes == {}


def test_every_module_is_not_judged_in_both_modes(table: Path) -> None:
    for mode in ("reference", "corrected"):
        document = diagnose(read(table), make_params(mode)).to_json()
        assert all(v.startswith("not judged") for v in document["modules_judged"].values())
        # Naturalistic driving records no collision: unknown, never "no collision".
        assert document["verdict"].startswith("inconclusive: collision unknown (")
        assert document["collision"] == "unknown" and document["conclusive"] is False


# --- scores ------------------------------------------------------------------------------------


def test_submission_scores_are_the_hand_computed_ones(table: Path) -> None:
    log = read(table, write_submission(table / "sub.csv", hand_paths()))
    assert problems_of(log) == []
    snap = log.ego_snapshots
    assert snap is not None and snap.submission.endswith("sub.csv")
    # The predicted path is mirrored as the realised one: row 2's y of +0.4 reads -0.4.
    np.testing.assert_allclose(snap.predicted[2][:, 1], -0.4)
    scores = scores_of(log)
    assert scores["scored"] == 3 and scores["no_truth"] == 0 and scores["no_prediction"] == 0
    assert scores["mae"] == pytest.approx(HAND_MAE, abs=1e-12)
    np.testing.assert_allclose(scores["per_row"]["ade"], HAND_ADE)
    np.testing.assert_allclose(scores["per_row"]["fde"], HAND_FDE)
    # Row MAEs: 6 / 18, 1.8 / 18, 5.4 / 18.
    np.testing.assert_allclose(scores["per_row"]["mae"], [6 / 18, 1.8 / 18, 5.4 / 18])
    assert scores["ade"] == pytest.approx(sum(HAND_ADE) / 3)
    assert scores["fde"] == pytest.approx(sum(HAND_FDE) / 3)
    # Axes: x (6 x 1 + 3) / 18 = 0.5; y 2.4 / 18; z 1.8 / 18.
    assert scores["mae_by_axis"] == pytest.approx({"x": 0.5, "y": 2.4 / 18, "z": 0.1})
    horizons = scores["by_horizon"]
    assert [h["horizon_s"] for h in horizons] == [0.5, 1.0, 1.5, 2.0, 2.5, 3.0]
    assert horizons[0]["distance"] == pytest.approx((1.0 + 0.3 + 0.4) / 3)
    assert horizons[5]["distance"] == pytest.approx((1.0 + 0.3 + ROW2_FDE) / 3)
    # At 3.0 s the |errors| are row 0: 1, row 1: 0.3, row 2: 3 + 0.4, over 9 values.
    assert horizons[5]["mae"] == pytest.approx((1.0 + 0.3 + 3.4) / 9)
    # Worst first: row 0 (ADE 1), row 2 (0.838), row 1 (0.3).
    assert [w["id"] for w in scores["worst_rows"]] == [IDS[0], IDS[2], IDS[1]]
    assert scores["worst_rows"][1]["timestamp_ms"] == 200


def test_a_perfect_submission_scores_zero(table: Path) -> None:
    log = read(table, write_submission(table / "sub.csv", [r.path for r in ROWS]))
    scores = scores_of(log)
    assert scores["mae"] == 0.0 and scores["ade"] == 0.0 and scores["fde"] == 0.0


def test_id_matched_submission_in_another_order_scores_the_same(table: Path) -> None:
    paths = hand_paths()
    order = [2, 0, 1]
    sub = write_submission(table / "sub.csv", [paths[n] for n in order], [IDS[n] for n in order])
    log = read(table, sub)
    assert problems_of(log) == []
    assert log.metadata.raw["submission"]["matched_by"] == "ID"
    assert scores_of(log)["mae"] == pytest.approx(HAND_MAE, abs=1e-12)


def test_id_matched_submission_reports_unknown_and_missing_ids(table: Path) -> None:
    paths = hand_paths()
    ids = [IDS[0], f"{SCENE_A}_999", "bad\x1b[2Jid"]
    log = read(table, write_submission(table / "sub.csv", paths, ids))
    problems = problems_of(log)
    assert any("2 IDs are no row of the table" in p for p in problems), problems
    assert any("2 table rows have no prediction" in p for p in problems), problems
    scores = scores_of(log)
    # Only row 0 is scored: its 6 x errors of 1 over 18 values.
    assert scores["scored"] == 1 and scores["no_prediction"] == 2
    assert scores["mae"] == pytest.approx(6 / 18)
    text = "\n".join(str(p) for p in log.problems)
    assert "\x1b" not in text  # the hostile ID is escaped in the problem line


def test_too_few_and_too_many_rows(table: Path) -> None:
    paths = hand_paths()
    log = read(table, write_submission(table / "few.csv", paths[:2]))
    assert any("2 rows for the table's 3" in p for p in problems_of(log))
    scores = scores_of(log)
    # Rows 0 and 1: (6 + 1.8) / 36.
    assert scores["scored"] == 2 and scores["mae"] == pytest.approx(7.8 / 36)
    log = read(table, write_submission(table / "many.csv", [*paths, paths[0]]))
    assert any("4 rows for the table's 3: the last 1" in p for p in problems_of(log))
    assert scores_of(log)["mae"] == pytest.approx(HAND_MAE)


def test_nan_text_and_short_rows_in_a_submission_leave_the_rest_scored(table: Path) -> None:
    paths = hand_paths()
    sub = write_submission(table / "sub.csv", paths)
    lines = sub.read_text().splitlines()
    cells = lines[2].split(",")  # data row 2 (table row 1)
    cells[3] = "nan"
    lines[2] = ",".join(cells)
    cells = lines[3].split(",")
    lines[3] = ",".join(cells[:10])  # data row 3 cut short: 10 fields for 18
    sub.write_text("\n".join(lines) + "\n")
    log = read(table, sub)
    problems = problems_of(log)
    assert any("1 rows do not have the header's 18 fields" in p for p in problems), problems
    assert any("x_1: 1 rows: not a finite number" in p for p in problems), problems
    scores = scores_of(log)
    assert scores["scored"] == 1 and scores["mae"] == pytest.approx(6 / 18)
    cells = lines[1].split(",")
    cells[0] = "fast"
    lines[1] = ",".join(cells)
    sub.write_text("\n".join(lines) + "\n")
    log = read(table, sub)
    assert any("x_0: 1 rows: not a finite number (the first: data row 1, 'fast')" in p
               for p in problems_of(log))  # fmt: skip
    assert scores_of(log)["scored"] == 0


def huge_paths(rows: int) -> list[Path3]:
    """Paths of ±1e308 m: finite, but their differences and squares overflow."""
    return [tuple((1e308 if n % 2 else -1e308, -1e308, 1e308) for n in range(6))] * rows


def test_a_submission_of_huge_figures_is_input_problems_not_scores(table: Path) -> None:
    """±1e308 everywhere (issue 43, item 6d): it printed numpy's overflow warnings and
    'MAE None' while claiming '3 of 3 rows scored' and 0 input problems."""
    sub = write_submission(table / "sub.csv", huge_paths(len(ROWS)))
    done = run_script("diagnose", str(table), "--submission", str(sub))
    assert done.returncode == 0, done.stderr
    assert done.stderr == ""  # no RuntimeWarning: overflow encountered ...
    assert "MAE None" not in done.stdout and "None m" not in done.stdout
    assert f"trajectory scores (0 of {len(ROWS)} rows scored)" in done.stdout, done.stdout
    assert "input problems: 18" in done.stdout, done.stdout
    assert (
        f"sub.csv: x_0: {len(ROWS)} rows: beyond ±1e+150, too large to compute with (the "
        "first: data row 1, '-1e+308')" in done.stdout
    )


def test_one_huge_row_is_a_problem_and_the_rest_scored(table: Path) -> None:
    paths = hand_paths()
    paths[1] = huge_paths(1)[0]
    log = read(table, write_submission(table / "sub.csv", paths))
    assert sum("too large to compute with" in p for p in problems_of(log)) == 18
    scores = scores_of(log)
    assert scores["scored"] == 2 and scores["no_prediction"] == 1
    assert scores["mae"] == pytest.approx((6 + 5.4) / 36)


def test_scores_without_finite_figures_are_not_shown_as_none() -> None:
    from ads_rca.sources.atmacup.trajectory_scores import trajectory_lines

    lines = trajectory_lines(
        {"rows": 3, "scored": 3, "no_truth": 0, "no_prediction": 0, "mae": None, "ade": None}
    )
    assert lines == [
        "trajectory scores (3 of 3 rows scored; 0 without a realised path, 0 without a "
        "prediction): MAE, ADE, FDE: not computed (a figure is no finite number)"
    ]


def test_a_submission_lacking_a_column_is_one_line(table: Path) -> None:
    sub = table / "sub.csv"
    header = ",".join(TARGETS[:-1])
    sub.write_text(header + "\n" + ",".join(["0"] * 17) + "\n")
    with pytest.raises(InputError, match="no column z_5"):
        read(table, sub)
    done = run_script("diagnose", str(table), "--submission", str(sub))
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and "no column z_5" in done.stderr
    done = run_script("diagnose", str(table), "--submission", str(table / "missing.csv"))
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1


def test_a_test_table_has_nothing_to_score(tmp_path: Path) -> None:
    write_table(tmp_path, train=False)
    log = read(tmp_path, write_submission(tmp_path / "sub.csv", hand_paths()))
    assert problems_of(log) == [] and (tmp_path / TEST).is_file()
    assert log.ego_snapshots is not None and not log.ego_snapshots.has_truth
    scores = scores_of(log)
    assert scores["scored"] == 0 and scores["no_truth"] == 3
    assert "test table has no targets" in scores["note"]


# --- hostile tables ----------------------------------------------------------------------------


def test_text_nan_missing_columns_and_bad_ids_are_reported_the_rest_read(tmp_path: Path) -> None:
    path = write_table(tmp_path)
    lines = path.read_text().splitlines()
    header = lines[0].split(",")
    gone = header.index("aEgo")
    rows = [line.split(",") for line in lines[1:]]
    rows[0][header.index("vEgo")] = "fast"
    rows[1][header.index("y_2")] = "nan"
    rows[1][header.index("gearShifter")] = "warp"
    rows[2][header.index("leftBlinker")] = "maybe"
    extra = [*rows[0]]
    extra[0] = "../../etc/passwd_1"  # no ID: never a file name
    again = [*rows[2]]  # the same ID twice: the first kept
    table = [header, *rows, extra, again]
    path.write_text("\n".join(",".join(c for n, c in enumerate(r) if n != gone) for r in table))
    log = read(tmp_path)
    problems = problems_of(log)
    assert f"{TRAIN} aEgo: missing columns (read as NaN)" in problems
    assert any("vEgo: 1 rows: not a finite number (the first: row " in p for p in problems)
    assert any("y_2: 1 rows: not a finite number" in p for p in problems)
    assert any("gearShifter: 1 rows: not one of drive" in p for p in problems)
    assert any("leftBlinker: 1 rows: not true or false" in p for p in problems)
    assert any("ID: 1 rows: not an ID" in p and "frame skipped" in p for p in problems)
    assert any("ID: 1 rows repeat an earlier row's ID" in p for p in problems)
    assert log.frames == (0, 100, 200)
    snap = log.ego_snapshots
    assert snap is not None
    assert math.isnan(snap.vehicle["vEgo"][0]) and math.isnan(log.pose[0].speed)
    assert np.isnan(snap.vehicle["aEgo"]).all()
    assert snap.gear == ("drive", "unknown", "reverse")
    assert math.isnan(snap.vehicle["leftBlinker"][2])
    assert math.isnan(snap.realised[1, 2, 1]) and snap.realised[1, 2, 0] == 0.0
    # A submission of every row: row 1's NaN truth leaves it unscored.
    log = read(tmp_path, write_submission(tmp_path / "sub.csv", [*hand_paths(), *hand_paths()]))
    scores = scores_of(log)
    assert scores["scored"] == 2 and scores["no_truth"] == 1
    # Rows 0 and 2 by file position (the skipped rows take their submission rows with them).
    assert scores["mae"] == pytest.approx((6 + 5.4) / 36)


@pytest.mark.parametrize(
    ("content", "expected"),
    [
        (b"", "empty file: no header row"),
        (b"\xff\xfe\x00junk", "not UTF-8 text"),
        (b"vEgo,aEgo\n1,2\n", "no ID column: not an atmaCup table"),
    ],
)
def test_an_unusable_table_is_one_line(tmp_path: Path, content: bytes, expected: str) -> None:
    (tmp_path / TRAIN).write_bytes(content)
    with pytest.raises(InputError, match=expected):
        read(tmp_path)
    done = run_script("diagnose", str(tmp_path))
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and expected in done.stderr


def test_a_fifo_named_like_a_table_is_refused(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / TRAIN)
    with pytest.raises(InputError, match=r"not a regular file \(FIFO\)"):
        read(tmp_path)


def test_a_cut_table_keeps_the_rows_before_the_cut(tmp_path: Path) -> None:
    path = write_table(tmp_path)
    text = path.read_text()
    path.write_text(text.rstrip("\n") + '\n"unclosed,1,2')
    log = read(tmp_path)
    assert log.frames == (0, 100, 200)  # the cut row has one field: reported, skipped
    assert any("do not have the header's" in p for p in problems_of(log))


def test_bad_traffic_light_files_are_counted_per_kind(table: Path) -> None:
    lights = table / LIGHTS
    (lights / f"{IDS[0]}.json").write_text('[{"index": 1, "class": "green", "bbox": [1, 2')
    (lights / f"{IDS[1]}.json").write_text('{"index": 1}')
    (lights / f"{IDS[2]}.json").write_text(
        json.dumps(
            [
                {"index": 1, "class": "green", "bbox": [1, 2, "3", 4]},
                {"index": True, "class": "purple", "bbox": [1, 2, 3, 4]},
                {"index": 1e300, "class": 7, "bbox": [5, 6, 7, 8]},
            ]
        )
    )
    log = read(table)
    problems = problems_of(log)
    assert any(p.startswith(f"{LIGHTS}/{IDS[0]}.json : invalid JSON") for p in problems), problems
    assert any("not a list of detections (1 files" in p for p in problems), problems
    assert any("bbox: not four finite numbers (1 files" in p for p in problems), problems
    assert any("index: not an integer" in p for p in problems), problems
    assert any("class: not one of green" in p for p in problems), problems
    assert 0 not in log.bboxes and 100 not in log.bboxes
    boxes = log.bboxes[200]  # the two usable detections, at their list positions
    assert boxes.ids == ("1", "2") and [e["label"] for e in boxes.extras] == ["other", "other"]
    assert boxes.corners.tolist() == [[1.0, 2.0, 3.0, 4.0], [5.0, 6.0, 7.0, 8.0]]


def test_a_row_without_a_traffic_light_file_is_one_warning(table: Path) -> None:
    (table / LIGHTS / f"{IDS[1]}.json").unlink()
    log = read(table)
    assert any(
        f"1 rows have no traffic-light file (the first: {IDS[1]})" in p for p in problems_of(log)
    )
    assert 100 not in log.bboxes and 0 in log.bboxes


# --- formats -------------------------------------------------------------------------------------


def test_format_detection_by_names(tmp_path: Path) -> None:
    path = write_table(tmp_path / "data")
    assert detect_format(path) == "atmacup" and detect_format(tmp_path / "data") == "atmacup"
    write_table(tmp_path / "test", train=False)
    assert detect_format(tmp_path / "test") == "atmacup"
    (tmp_path / "data" / "actors").mkdir()
    assert detect_format(tmp_path / "data") == "log"  # a running log wins over a stray table
    write_table(tmp_path / "both")
    write_table(tmp_path / "both", train=False)
    with pytest.raises(InputError, match="holds both of"):
        open_run(tmp_path / "both")
    log = open_run(tmp_path / "both" / TEST)
    assert log.metadata.raw["table"]["file"] == TEST


def test_submission_elsewhere_is_one_line(tmp_path: Path) -> None:
    from writers.carla_runs import write_carla_run

    sub = write_submission(tmp_path / "sub.csv", hand_paths())
    done = run_script("diagnose", str(write_carla_run(tmp_path / "run")), "--submission", str(sub))
    assert done.returncode == 2 and "--submission applies to atmaCup tables" in done.stderr


def test_diagnose_prints_the_scores_and_writes_them_in_the_json(table: Path) -> None:
    sub = write_submission(table / "sub.csv", hand_paths())
    out = table.parent / "verdict.json"
    done = run_script("diagnose", str(table), "--submission", str(sub), "--json", str(out))
    assert done.returncode == 0, done.stderr
    assert "trajectory scores (3 of 3 rows scored" in done.stdout
    assert "MAE 0.244444 (the competition's, over x, y, z)" in done.stdout  # 13.2 / 54
    assert f"    {IDS[0]}: ADE 1 m, FDE 1 m" in done.stdout
    assert "controller" in done.stdout and "not judged" in done.stdout
    document = json.loads(out.read_text())
    scores = document[TRAJECTORY_SCORES_KEY]
    assert scores["mae"] == pytest.approx(HAND_MAE) and scores["scored"] == 3
    assert document["modules_judged"]["controller"] == "not judged (no plan)"
    done = run_script("diagnose", str(table), "--format", "atmacup")
    assert done.returncode == 0 and "no submission given" in done.stdout


def test_a_batch_job_diagnoses_a_table_and_names_its_format(table: Path) -> None:
    from ads_rca.batch.work import Job, run_job
    from ads_rca.sources.bag.options import BagOptions

    job = Job("t1", str(table), make_params("corrected"), 64.0, BagOptions(), 60.0)
    outcome = run_job(job)
    assert outcome.row["format"] == "atmaCup table" and not outcome.row.get("error")
    assert outcome.json is not None and len(json.loads(outcome.json)["frames"]) == 3


def test_inspect_lists_the_capability_record(table: Path) -> None:
    done = run_script("inspect", str(table))
    assert done.returncode == 0, done.stderr
    assert "actors: derived" in done.stdout and "detections_2d: real" in done.stdout


# --- live: run/ego_paths -------------------------------------------------------------------------


def test_ego_path_messages_round_trip_and_rebuild_the_scores(table: Path) -> None:
    log = read(table, write_submission(table / "sub.csv", hand_paths()))
    assert topics.EGO_PATHS in topics.advertised(log)
    documents = [ego_path_document(log, ts) for ts in log.frames]
    assert ego_path_document(log, 50) is None  # no row there
    first = documents[0]
    assert first is not None and first["id"] == IDS[0] and first["row"] == 0
    assert first["realised"][1] == [10.0, -0.2, 0.02]  # mirrored, as in the snapshots
    rows = {}
    for document in documents:
        assert document is not None
        row = read_ego_path(loads_json(dumps_json(document)))
        rows[row.stamp_ms] = row
    rebuilt = trajectory_scores(snapshots_from_rows(rows))
    offline = scores_of(log)
    assert rebuilt == offline


def test_a_live_models_later_prediction_replaces_the_players(table: Path) -> None:
    log = read(table)
    player = read_ego_path(loads_json(dumps_json(ego_path_document(log, 0))))
    assert player.predicted is None and player.realised is not None
    guess = [[x + 1.0, -y, z] for x, y, z in ROWS[0].path]  # the model frame: y mirrored
    model = read_ego_path({"stamp_ms": 0, "predicted": guess, "submission": "my-model"})
    row = merged(player, model)
    assert row.ident == IDS[0] and row.submission == "my-model"
    scores = trajectory_scores(snapshots_from_rows({0: row}))
    assert scores["scored"] == 1 and scores["mae"] == pytest.approx(6 / 18)


@pytest.mark.parametrize(
    ("document", "expected"),
    [
        ({"id": "x"}, "stamp_ms is not a timestamp"),
        ({"stamp_ms": -1}, "stamp_ms is not a timestamp"),
        ({"stamp_ms": True}, "stamp_ms is not a timestamp"),
        ({"stamp_ms": 0, "id": 7}, "id and submission must be text"),
        ({"stamp_ms": 0, "id": "x" * 300}, "longer than 256"),
        ({"stamp_ms": 0, "row": "1"}, "row is not an integer"),
        ({"stamp_ms": 0, "realised": [[1, 2, 3]] * 5}, "realised is not six"),
        ({"stamp_ms": 0, "predicted": [[1, 2, "3"]] * 6}, "predicted is not six"),
        ({"stamp_ms": 0, "predicted": [[1, 2, True]] * 6}, "predicted is not six"),
    ],
)
def test_a_malformed_ego_path_message_is_refused(document: dict[str, Any], expected: str) -> None:
    with pytest.raises(MalformedMessage, match=expected):
        read_ego_path(document)


def test_each_frame_scores_its_row_in_the_planning_result(table: Path) -> None:
    log = read(table, write_submission(table / "sub.csv", hand_paths()))
    frames = diagnose(log, make_params("corrected")).to_json()["frames"]
    planning = [f["planning"] for f in frames]
    assert [p["row_id"] for p in planning] == IDS
    assert all(p["skipped"].startswith("not judged") and not p["failed"] for p in planning)
    np.testing.assert_allclose([p["trajectory_ade"] for p in planning], HAND_ADE)
    np.testing.assert_allclose([p["trajectory_fde"] for p in planning], HAND_FDE)
    np.testing.assert_allclose(
        [p["trajectory_mae"] for p in planning], [6 / 18, 1.8 / 18, 5.4 / 18]
    )
    reference = diagnose(log, make_params("reference")).to_json()["frames"]
    assert all("row_id" not in f["planning"] for f in reference)  # the reference's rules only
    plain = diagnose(read(table), make_params("corrected")).to_json()["frames"]
    assert all("row_id" not in f["planning"] for f in plain)  # no submission: nothing scored


def test_the_planning_monitor_waits_for_a_rows_paths_and_scores_it(table: Path) -> None:
    from ads_rca.live.diagnostics import OK, result_status
    from ads_rca.live.results import FrameMarker
    from ads_rca.live.window import MonitorCore

    log = read(table, write_submission(table / "sub.csv", hand_paths()))
    core = MonitorCore("planning", make_params("corrected"))
    core.set_metadata(log.metadata, 0.0)
    assert core.wants_paths
    marker = FrameMarker(0, 0, frozenset({"pose", "actors", "bboxes"}), snapshot=True)
    for folder in core.folders:
        record = log.folder(folder).get(0)
        if record is not None:
            core.add_record(folder, 0, record, 0.1)
    core.add_marker(marker, 0.1)
    core.set_finished(0.1, 1)  # one frame played: no look-ahead to wait for
    assert core.poll(0.2) == []  # the row's paths have not come
    document = ego_path_document(log, 0)
    assert document is not None
    core.add_ego_path(read_ego_path(loads_json(dumps_json(document))), 0.3)
    results = core.poll(0.3)
    assert len(results) == 1 and not results[0].incomplete
    metrics = results[0].result.metrics
    assert metrics["row_id"] == IDS[0] and metrics["trajectory_ade"] == pytest.approx(1.0)
    status = result_status(results[0], "corrected", "test")
    assert status.level == OK and f"row {IDS[0]}: predicted path scored" in status.message
    # A frame whose row never comes is judged when inputs time out, marked incomplete.
    late_core = MonitorCore("planning", make_params("corrected"))
    late_core.set_metadata(log.metadata, 0.0)
    late_core.add_marker(FrameMarker(0, 0, frozenset(), snapshot=True), 0.1)
    late_core.set_finished(0.1, 1)
    assert late_core.poll(0.2) == []
    late = late_core.poll(0.1 + late_core.settings.input_timeout_s + 1)
    assert len(late) == 1 and "no ego_paths record" in " ".join(late[0].incomplete)
    assert "row_id" not in late[0].result.metrics


def test_replay_of_a_table_scores_as_diagnose(ros_env: RosEnv, tmp_path: Path) -> None:
    """Player, monitors, aggregator and recorder over DDS: the player sends each row's paths
    on run/ego_paths and marks its frame as a snapshot; the live verdict's trajectory scores
    are diagnose's, and so are its input problems (the ego has no size: no check needs one)."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    table = tmp_path / "data"
    write_table(table)
    sub = write_submission(table / "sub.csv", hand_paths()).resolve()
    bag, out = tmp_path / "bag", tmp_path / "verdict.json"
    argv = [sys.executable, "-m", "ads_rca.cli", "replay", str(table), "--submission", str(sub)]
    argv += ["--record", str(bag), "--json", str(out), "--domain-id", str(ros_env.domain_id)]
    replay = ManagedProcess("replay", [*argv, "--timeout", "90"], ros_env.env)
    assert replay.wait(120) == 0, replay.output
    live = json.loads(out.read_text())
    offline = diagnose(read(table, sub), make_params("corrected")).to_json()
    for key in ("frames", "modules_judged", TRAJECTORY_SCORES_KEY, "verdict", "input_problems"):
        assert live[key] == offline[key], key
    assert live[TRAJECTORY_SCORES_KEY]["mae"] == pytest.approx(HAND_MAE)
    paths: list[dict[str, Any]] = []
    snapshots: list[str] = []
    with next(bag.glob("*.mcap")).open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _schema, channel, _raw, msg in reader.iter_decoded_messages(log_time_order=False):
            if channel.topic.endswith("/run/ego_paths"):
                paths.append(json.loads(msg.data))
            elif channel.topic.endswith("/run/frame"):
                snapshots.append(json.loads(msg.data).get("snapshot"))
    assert [p["id"] for p in paths] == IDS and snapshots == IDS
    assert [f["planning"]["row_id"] for f in live["frames"]] == IDS  # each row scored live
