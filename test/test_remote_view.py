"""The dashboards' model (``remote/view.py``): what it accepts from the wire and what it counts.

Pure: no Zenoh here (the sessions are tested in test_ros_zenoh_bridge, test_remote_watch and
test_remote_dashboard). Keys: samples end in ``.json``, queryable replies do not, raw CDR keys are
neither; a run's counts survive re-judged frames and restart with a new run id. Verdicts
(docs/verdicts.md): conclusion fields of the wrong type are refused, an inconclusive or
unstated verdict never reads as "no fault found", and each module's state is the verdict's
when it was not judged.
"""

from __future__ import annotations

import io
import json
from typing import Any

import pytest
from rich.console import Console

from ads_rca.capabilities import JUDGED, NOT_JUDGED
from ads_rca.diagnosis.conclusion import PARTLY_JUDGED
from ads_rca.remote.view import (
    BLAMED,
    FAILING,
    INCOMPLETE,
    INCONCLUSIVE,
    INTERNAL_ERROR,
    MAX_RUNS,
    NO_FAULT_FOUND,
    OK,
    ROOT_CAUSE,
    SKIPPED,
    UNSTATED,
    WAITING,
    DashboardModel,
    module_state,
    parse_key,
    read_verdict,
)
from ads_rca.remote.watch import module_table


def result(index: int, module: str = "planning", failed: bool = False, **extra: Any) -> str:
    document = {
        "module": module,
        "index": index,
        "frame": index + 1,
        "failed": failed,
        "metrics": {"c_gt": 2.0 - index * 0.5},
        "thresholds": {"safety_margin": 0.5},
        "run": "r1",
        **extra,
    }
    return json.dumps(document)


def test_keys_samples_replies_and_raw_cdr() -> None:
    assert parse_key("car1/ads_rca/modules/planning.json") == ("car1", "modules", "planning")
    assert parse_key("ads_rca/verdict.json") == ("", "verdict", None)
    assert parse_key("fleet/ads_rca/ads_rca/status.json") == ("fleet/ads_rca", "status", None)
    assert parse_key("car1/ads_rca/frames") == ("car1", "frames", None)  # a reply
    assert parse_key("car1/ads_rca/verdict") == ("car1", "verdict", None)  # a reply
    for raw in (
        "car1/ads_rca/verdict/json",  # the raw CDR of /ads_rca/verdict/json
        "car1/ads_rca/metrics/planning",
        "car1/ads_rca/frames.json",  # frames are only ever a reply
        "car1/ads_rca/modules/wheels.json",
        "car1/ads_rca/modules/planning",  # a module is only ever a sample
    ):
        assert parse_key(raw) is None, raw


def test_counts_near_misses_and_re_judged_frames() -> None:
    model = DashboardModel()
    for index in range(5):
        model.apply("c/ads_rca/modules/planning.json", result(index, failed=index >= 3), 1.0)
    model.apply("c/ads_rca/modules/planning.json", result(4, failed=False), 2.0)  # re-judged
    run = model.summary(2.0)["runs"][0]
    assert run["run_id"] == "r1" and run["last_index"] == 4
    assert run["modules"]["planning"]["judged"] == 5
    assert run["modules"]["planning"]["failed_frames"] == 1
    # c_gt 0.0 < 0.5 at frame 4, judged twice: one near miss, the latest judgement's
    assert [(m["index"], m["clearance"]) for m in run["near_misses"]] == [(4, 0.0)]
    assert list(model.runs["c@r1"].timeline) == [(i, 2.0 - i * 0.5) for i in range(5)]


def test_a_re_judged_frame_is_one_near_miss_with_its_latest_clearance() -> None:
    model = DashboardModel()
    for index in range(5):  # c_gt 2.0 - 0.5 * index: only frame 4 (0.0) is below 0.5
        model.apply("c/ads_rca/modules/planning.json", result(index), 1.0)
    rejudged = [(2, 0.1), (4, 0.2), (2, 0.3), (4, 0.9)]  # frame 4 ends above the margin
    for index, clearance in rejudged:
        document = result(index, metrics={"c_gt": clearance})
        model.apply("c/ads_rca/modules/planning.json", document, 2.0)
    run = model.summary(2.0)["runs"][0]
    assert [(m["index"], m["clearance"]) for m in run["near_misses"]] == [(2, 0.3)]
    assert run["modules"]["planning"]["judged"] == 5


def test_a_new_run_under_the_same_prefix_is_a_run_of_its_own() -> None:
    model = DashboardModel()
    model.apply("c/ads_rca/modules/planning.json", result(0, failed=True), 1.0)
    model.apply("c/ads_rca/modules/planning.json", result(0, run="r2"), 2.0)
    first, second = model.summary(2.0)["runs"]
    assert (first["name"], first["run_id"], second["name"], second["run_id"]) == (
        "c@r1",
        "r1",
        "c@r2",
        "r2",
    )
    assert second["modules"]["planning"] == {**second["modules"]["planning"], "judged": 1}
    assert second["modules"]["planning"]["failed_frames"] == 0
    assert first["modules"]["planning"]["failed_frames"] == 1


def test_a_stray_sample_of_another_run_never_erases_a_run() -> None:
    """Issue 38 item 5: one forged sample naming another run, then the two runs' samples
    interleaved, then a verdict for each: every count and verdict stays with its run."""
    model = DashboardModel()
    key = "car1/ads_rca/modules/planning.json"
    for index in range(10):
        model.apply(key, result(index, failed=index == 7), 1.0 + index)
    event = model.apply(key, result(3, run="forged"), 20.0)
    assert event is not None and event["name"] == "car1@forged"
    for index in range(10, 20):  # two runs under one prefix, interleaved
        model.apply(key, result(index), 21.0 + index)
        model.apply(key, result(index - 10, run="r2", failed=True), 21.5 + index)
    for at, run in enumerate(("r1", "r2")):
        document = {"primary_root_cause": "planning" if run == "r2" else None}
        verdict = {**document, "live": {"run": run}, "conclusive": True, "collision": "yes"}
        model.apply("car1/ads_rca/verdict.json", json.dumps(verdict), 50.0 + at)
    runs = {run["name"]: run for run in model.summary(51.0)["runs"]}
    assert sorted(runs) == ["car1@forged", "car1@r1", "car1@r2"]
    judged = {
        name: (r["modules"]["planning"]["judged"], r["modules"]["planning"]["failed_frames"])
        for name, r in runs.items()
    }
    assert judged == {"car1@r1": (20, 1), "car1@r2": (10, 10), "car1@forged": (1, 0)}
    assert runs["car1@r1"]["last_index"] == 19 and runs["car1@r2"]["last_index"] == 9
    assert runs["car1@r1"]["verdict"]["primary_root_cause"] is None
    assert runs["car1@r2"]["verdict"]["primary_root_cause"] == "planning"
    assert runs["car1@forged"]["verdict"] is None
    # A bare prefix (a hand-typed URL) names its run updated last.
    found = model.find("car1")
    assert found is not None and found.run_id == "r2"


def test_documents_naming_no_run_join_the_prefix_s_run() -> None:
    """A bridge's status beside a stack names no run: it goes to the prefix's run updated
    last; a status first, then results naming a run, make one run, not two."""
    model = DashboardModel()
    status = {"state": "running", "run": ""}
    model.apply("s/ads_rca/status.json", json.dumps(status), 1.0)
    model.apply("s/ads_rca/modules/planning.json", result(0), 2.0)
    model.apply("s/ads_rca/modules/planning.json", result(0, run="r2"), 3.0)
    model.apply("s/ads_rca/status.json", json.dumps({**status, "state": "verdict"}), 4.0)
    runs = {run["name"]: run for run in model.summary(4.0)["runs"]}
    assert sorted(runs) == ["s@r1", "s@r2"]
    assert runs["s@r1"]["status"]["state"] == "running"
    assert runs["s@r2"]["status"]["state"] == "verdict"


@pytest.mark.parametrize("run", [7, True, [], {}, "a b", "r" * 65, "<b>", "run@1", "../x"])
def test_a_run_that_is_no_run_id_is_a_problem(run: object) -> None:
    model = DashboardModel()
    model.apply("c/ads_rca/modules/planning.json", result(0), 1.0)
    document = {**json.loads(result(1)), "run": run}
    assert model.apply("c/ads_rca/modules/planning.json", json.dumps(document), 2.0) is None
    verdict = {"primary_root_cause": None, "live": {"run": run}}
    assert model.apply("c/ads_rca/verdict.json", json.dumps(verdict), 2.0) is None
    assert model.problems == 2 and "run id" in model.last_problem
    assert [r["name"] for r in model.summary(2.0)["runs"]] == ["c@r1"]
    assert model.apply("a@b/ads_rca/modules/planning.json", result(0), 2.0) is None
    assert model.problems == 3 and [r["name"] for r in model.summary(2.0)["runs"]] == ["c@r1"]


def test_a_frames_reply_fills_what_rate_limits_skipped() -> None:
    model = DashboardModel()
    model.apply("c/ads_rca/modules/planning.json", result(9), 1.0)
    frames = [{"index": i, "modules": {"planning": json.loads(result(i))}} for i in range(10)]
    event = model.apply("c/ads_rca/frames", json.dumps({"since": -1, "frames": frames}), 2.0)
    assert event == {"run": "c", "kind": "frames", "results": 10, "runs": ["c@r1"]}
    assert model.summary(2.0)["runs"][0]["modules"]["planning"]["judged"] == 10


@pytest.mark.parametrize(
    ("key", "payload"),
    [
        ("c/ads_rca/modules/planning.json", b"{"),
        ("c/ads_rca/modules/planning.json", b'{"x": NaN}'),  # not strict JSON
        ("c/ads_rca/modules/planning.json", b"[1]"),
        ("c/ads_rca/modules/planning.json", b'{"index": "3"}'),
        ("c/ads_rca/modules/planning.json", b'{"index": true}'),
        ("c/ads_rca/verdict.json", b'{"verdict": "x"}'),  # no primary_root_cause
        ("c/ads_rca/frames", b'{"frames": [1]}'),
        ("c/ads_rca/frames", b'{"frames": "all"}'),
        ("\x1b[2J/ads_rca/wheels", b"{}"),
        ("c/ads_rca/status.json", b"\xff\xfe"),
    ],
)
def test_what_is_not_ours_is_counted_and_dropped(key: str, payload: bytes) -> None:
    model = DashboardModel()
    assert model.apply(key, payload, 1.0) is None
    assert model.problems == 1
    assert "\x1b" not in model.last_problem and "\n" not in model.last_problem
    assert all(not view.modules and view.verdict is None for view in model.runs.values())


def test_runs_are_bounded_and_one_prefix_can_be_watched_alone() -> None:
    model = DashboardModel()
    for n in range(MAX_RUNS + 10):
        model.apply(f"car{n}/ads_rca/status.json", b'{"state": "running"}', float(n))
    assert len(model.runs) == MAX_RUNS and "car0" not in model.runs
    only = DashboardModel(prefix="car1")
    assert only.apply("car2/ads_rca/status.json", b"{}", 1.0) is None and only.problems == 0
    assert only.apply("car1/ads_rca/status.json", b"{}", 1.0) is not None


#: A live verdict as the aggregator gives it when the run lacks detections and a collision
#: source (docs/verdicts.md): no root cause, inconclusive.
INCONCLUSIVE_VERDICT: dict[str, Any] = {
    "primary_root_cause": None,
    "verdict": "inconclusive: collision unknown (no source); perception not judged (no x)",
    "reason": "collision unknown",
    "conclusive": False,
    "why_inconclusive": ["collision unknown (no source)", "perception not judged (no x)"],
    "collision": "unknown",
    "collision_frame": -1,
    "internal_errors": [],
    "modules_judged": {
        "perception": "not judged (no x)",
        "prediction": "partly judged (2 of 21 window frames: missing y at frames 70, 71)",
        "planning": "not judged: internal error (ZeroDivisionError: boom) at frame 3",
        "controller": "judged",
    },
    "live": {"run": "r1"},
}


@pytest.mark.parametrize(
    "change",
    [
        {"conclusive": "true"},
        {"conclusive": 1},
        {"conclusive": None},
        {"why_inconclusive": "collision unknown"},
        {"why_inconclusive": [1]},
        {"collision": "maybe"},
        {"collision": False},
        {"internal_errors": "planning"},
        {"modules_judged": {"perception": 3}},
        {"modules_judged": ["judged"]},
        {"conclusive": True},  # yet it lists why not
        {"conclusive": True, "why_inconclusive": [], "internal_errors": [{"module": "x"}]},
        # the fields a dashboard shows, of another shape
        {"primary_root_cause": {"module": "planning"}},
        {"primary_root_cause": ["planning"]},
        {"primary_root_cause": 3},
        {"contributing": "planning"},
        {"root_causes": [{"m": 1}]},
        {"attribution_basis": ["judged"]},
        {"semantics": 1},
        {"verdict": {"text": "x"}},
        {"collision_frame": "81"},
        {"collision_frame": True},
        {"collision_frame": 8.5},
        {"partner_id": {"id": 7}},
        {"partner_id": False},
        {"thresholds": [1, 2]},
        {"evidence": "all"},
        {"modules": []},
    ],
)
def test_a_verdict_with_unreadable_conclusion_fields_is_counted_and_dropped(
    change: dict[str, Any],
) -> None:
    model = DashboardModel()
    document = {**INCONCLUSIVE_VERDICT, **change}
    assert model.apply("c/ads_rca/verdict.json", json.dumps(document), 1.0) is None
    assert model.problems == 1 and "verdict" in model.last_problem
    assert all(view.verdict is None for view in model.runs.values())


def test_an_inconclusive_verdict_reads_inconclusive_and_its_modules_as_the_verdict_says() -> None:
    model = DashboardModel()
    model.apply("c/ads_rca/modules/controller.json", result(0, "controller"), 1.0)
    model.apply("c/ads_rca/modules/planning.json", result(0), 1.0)
    event = model.apply("c/ads_rca/verdict.json", json.dumps(INCONCLUSIVE_VERDICT), 1.0)
    assert event is not None and event["conclusive"] is False
    reading = read_verdict(INCONCLUSIVE_VERDICT)
    assert (reading.kind, reading.conclusive, reading.stated) == (INCONCLUSIVE, False, True)
    assert reading.collision == "unknown" and reading.text == INCONCLUSIVE_VERDICT["verdict"]
    assert reading.reasons == tuple(INCONCLUSIVE_VERDICT["why_inconclusive"])
    modules = model.summary(2.0)["runs"][0]["modules"]
    states = {m: (e["state"], e["detail"]) for m, e in modules.items()}
    judged = INCONCLUSIVE_VERDICT["modules_judged"]
    assert states == {
        "perception": (NOT_JUDGED, judged["perception"]),
        "prediction": (PARTLY_JUDGED, judged["prediction"]),
        "planning": (INTERNAL_ERROR, judged["planning"]),  # its latest result passed
        "controller": (OK, ""),
    }


def test_a_verdict_that_does_not_say_conclusive_is_not_shown_conclusive() -> None:
    """An older bridge's verdict: its "no fault found" was never checked against its
    evidence, so it reads as inconclusive, never as "no fault found"."""
    old = {
        "primary_root_cause": None,
        "verdict": "no fault found (no module failed)",
        "reason": "no module failed",
        "collision_frame": -1,
    }
    model = DashboardModel()
    event = model.apply("c/ads_rca/verdict.json", json.dumps(old), 1.0)
    assert event is not None and event["conclusive"] is False  # accepted, not conclusive
    reading = read_verdict(old)
    assert (reading.kind, reading.conclusive, reading.stated) == (INCONCLUSIVE, False, False)
    assert reading.text == f"inconclusive: {UNSTATED}" and reading.reasons == (UNSTATED,)
    assert reading.collision == "unknown"
    blamed = read_verdict({**old, "primary_root_cause": "planning", "verdict": "planning"})
    assert (blamed.kind, blamed.conclusive, blamed.text) == (ROOT_CAUSE, False, "planning")
    assert read_verdict({**old, "collision_frame": 81}).collision == "yes"


def test_only_a_conclusive_verdict_without_a_root_cause_is_no_fault_found() -> None:
    conclusive = {
        **INCONCLUSIVE_VERDICT,
        "verdict": "no fault found (no collision)",
        "conclusive": True,
        "why_inconclusive": [],
        "collision": "no",
    }
    reading = read_verdict(conclusive)
    assert (reading.kind, reading.conclusive, reading.reasons) == (NO_FAULT_FOUND, True, ())
    # Inconclusive, yet its sentence says otherwise: the sentence shown never does.
    lying = {**INCONCLUSIVE_VERDICT, "verdict": "no fault found (no collision)"}
    assert read_verdict(lying).text == "inconclusive: " + "; ".join(
        INCONCLUSIVE_VERDICT["why_inconclusive"]
    )


def test_a_latest_result_that_raised_or_was_not_judged_is_shown_as_such() -> None:
    assert module_state(None, None) == (WAITING, "")
    raised = {"failed": False, "skipped": "internal error (E: x)", "internal_error": "E: x"}
    assert module_state(raised, None) == (INTERNAL_ERROR, "internal error (E: x)")
    unjudged = {"failed": False, "skipped": "not judged (no detections_2d)"}
    assert module_state(unjudged, JUDGED) == (NOT_JUDGED, "not judged (no detections_2d)")
    assert module_state({"skipped": "missing pose"}, None) == (SKIPPED, "missing pose")
    assert module_state({"missing_input": True}, None) == (INCOMPLETE, "")
    assert module_state({"failed": True}, "judged") == (FAILING, "")
    assert module_state({"failed": False}, None) == (OK, "")


@pytest.mark.parametrize("value", [True, "true", 1, None])
def test_a_provisional_result_is_shown_provisional_until_its_final_one(value: object) -> None:
    """A replay's monitors judge frames provisionally as it plays (the collision partner
    not known yet); the final result of the frame replaces it. Only a literal true is
    provisional: anything else on the wire is not taken as a mark."""
    model = DashboardModel()
    model.apply("c/ads_rca/modules/planning.json", result(3, provisional=value), 1.0)
    module = model.summary(1.0)["runs"][0]["modules"]["planning"]
    assert module["provisional"] is (value is True)
    assert module["state"] == OK and module["judged"] == 1
    buffer = io.StringIO()
    Console(file=buffer, width=120).print(module_table(model.summary(1.0)["runs"][0]["modules"]))
    assert ("OK (provisional)" in buffer.getvalue()) is (value is True)
    model.apply("c/ads_rca/modules/planning.json", result(3, failed=True), 2.0)
    module = model.summary(2.0)["runs"][0]["modules"]["planning"]
    assert module["provisional"] is False
    assert (module["state"], module["judged"], module["failed_frames"]) == (FAILING, 1, 1)


def test_the_frame_rate_of_a_burst_is_frames_per_second_not_per_millisecond() -> None:
    """The end of a corrected run comes in one burst (every frame judged at once): it
    read "199191.9 frames/s". A rate is measured over at least a second, up to now."""
    model = DashboardModel()
    for index in range(100):  # 20 Hz for 5 s
        model.apply("c/ads_rca/modules/planning.json", result(index), 1.0 + index * 0.05)
    steady = model.runs["c@r1"].rate(1.0 + 99 * 0.05)
    assert 19.0 <= steady <= 21.0
    for index in range(100, 300):  # 200 frames within 10 ms
        model.apply("c/ads_rca/modules/planning.json", result(index), 7.0 + index * 0.00005)
    assert model.runs["c@r1"].rate(7.02) <= 200.0
    assert model.runs["c@r1"].rate(9.0) <= 100.0  # decays as time passes
    assert model.runs["c@r1"].rate(20.0) == 0.0  # idle


def test_the_module_a_verdict_blames_is_never_shown_ok() -> None:
    """A root cause's failure is in the effect window; its latest frame may pass. The
    table said a green "ok" for the blamed module: it says root cause now."""
    model = DashboardModel()
    model.apply("c/ads_rca/modules/planning.json", result(3), 1.0)
    model.apply("c/ads_rca/modules/perception.json", result(3, "perception", failed=True), 1.0)
    verdict = {**INCONCLUSIVE_VERDICT, "primary_root_cause": "planning", "root_causes": []}
    verdict |= {"conclusive": True, "why_inconclusive": [], "modules_judged": {}}
    assert model.apply("c/ads_rca/verdict.json", json.dumps(verdict), 2.0) is not None
    modules = model.summary(2.0)["runs"][0]["modules"]
    assert modules["planning"]["state"] == BLAMED
    assert modules["planning"]["detail"] == "root cause in the verdict (latest frame ok)"
    assert modules["perception"]["state"] == FAILING  # failing, not blamed


def test_a_table_shows_the_key_metrics_of_a_result_not_all_of_them() -> None:
    """A result carries 20-30 metrics; the dashboards show the module's key ones first,
    at most :data:`METRICS_SHOWN`."""
    from ads_rca.remote.view import METRICS_SHOWN

    metrics = {f"m{i}": float(i) for i in range(25)} | {"c_gt": 1.0, "ttc_gt": 2.0}
    model = DashboardModel()
    model.apply("c/ads_rca/modules/planning.json", result(3, metrics=metrics), 1.0)
    shown = model.summary(1.0)["runs"][0]["modules"]["planning"]["key_metrics"]
    assert shown[:2] == ["c_gt", "ttc_gt"] and len(shown) == METRICS_SHOWN
    assert model.summary(1.0)["runs"][0]["modules"]["perception"]["key_metrics"] == []


def test_verdict_documents_are_bounded_in_bytes_and_lose_their_frames(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Issue 41 item 7: the per-frame list is counted, not kept; the documents kept for
    download together stay under the bound, the runs updated longest ago let go first."""
    import ads_rca.remote.view as view_module

    monkeypatch.setattr(view_module, "MAX_VERDICT_BYTES", 3000)  # two of the three
    model = DashboardModel()
    for n in range(3):
        verdict: dict[str, Any] = {
            "primary_root_cause": None,
            "live": {"run": f"r{n}"},
            "frames": [{}] * 300,
        }
        model.apply("car1/ads_rca/verdict.json", json.dumps(verdict), float(n))
    runs = {name: model.runs[name] for name in model.runs}
    assert [runs[f"car1@r{n}"].verdict_payload is not None for n in range(3)] == [
        False,
        True,
        True,
    ]
    for n in range(3):
        kept = runs[f"car1@r{n}"]
        assert kept.verdict is not None and "frames" not in kept.verdict
        assert kept.verdict_frames == 300
    assert model.apply("car1/ads_rca/modules/planning.json", "x" * (1 << 20) + "y", 4.0) is None
    assert "payload larger than 1048576 bytes" in model.last_problem
