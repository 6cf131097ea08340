"""Stack mode over real DDS, each node its own process, beside a test stack.

The test stack (test/stack_publisher.py) publishes a synthesised crash as a stack does: its
own header stamps offset per topic (up to 20 ms), arrival jitter, ``/clock``, no frame
markers, no metadata, the collision announced on ``run/collision`` after the collision
frame. The ``monitors`` and ``aggregator`` nodes run in stack mode from parameters only.
With no loss the verdict and every judged frame equal ``diagnose``; an input dropped is
reported incomplete; an input never published makes the modules reading it STALE, not OK.
The whole grid (every crash, both modes, drops) runs in-process in test_live_stack_mode.py; here
one crash per scenario, each with a different fault, covers the four faults over DDS.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import RosEnv
from stackgraph import latest_results, metrics_difference, run_stack_graph, same_verdict

from ads_rca.diagnosis.engine import diagnose
from ads_rca.diagnosis.verdict import MODULES
from ads_rca.params import make_params
from ads_rca.synth import synthesise

pytestmark = pytest.mark.timeout(240)

#: One crash per scenario; the faults cover all four modules.
CRASHES = [
    ("cut_in", "perception"),
    ("lead_braking", "prediction"),
    ("pedestrian_crossing", "planning"),
    ("left_turn", "controller"),
]
RUN_FACTS = {"timesteps_per_frame": 50, "camera_loc.x": 1.3, "camera_loc.z": 1.8}
#: With no loss nothing is ever missing: a long timeout only keeps a loaded machine (a CI
#: run beside other work) from releasing a frame whose inputs DDS delivers late (and the
#: aggregator then waits for it: after_publisher_s covers input_timeout_s + verdict_timeout_s).
NO_LOSS = {"input_timeout_s": 30.0}


def sync_lines(outputs: dict[str, str]) -> list[str]:
    """What the monitors said their stamp sync dropped (why a frame was incomplete)."""
    return [line for line in outputs["monitors"].splitlines() if "stamp sync" in line]


@pytest.mark.parametrize("semantics", ["reference", "corrected"])
@pytest.mark.parametrize(("scenario", "fault"), CRASHES)
def test_the_verdict_beside_a_stack_equals_diagnose(
    ros_env: RosEnv, tmp_path: Path, scenario: str, fault: str, semantics: str
) -> None:
    log = synthesise(scenario, fault, 1)
    params = make_params(semantics)
    offline = diagnose(log, params)
    run = run_stack_graph(
        ros_env.env,
        tmp_path,
        f"{scenario}:{fault}:1",
        {
            "semantics": semantics,
            "topic_namespace": ros_env.namespace,
            "history_frames": 400,
            **RUN_FACTS,
            **NO_LOSS,
        },
        ["--namespace", ros_env.namespace, "--seed", "3", "--jitter-ms", "30"],
        # The verdict may wait input_timeout_s + verdict_timeout_s for a late input.
        after_publisher_s=60.0,
    )
    [verdict] = run.verdicts
    expected = offline.to_json()
    assert verdict["live"]["complete"] is True, (verdict["live"], sync_lines(run.outputs))
    assert same_verdict(verdict, expected)
    assert verdict["live"]["collision_number"] == 1
    heard = [f"first result from the {m} monitor" in run.outputs["aggregator"] for m in MODULES]
    assert all(heard), run.outputs["aggregator"]  # said once each, in the log
    judged = latest_results(run.results)
    assert {stamp for _, stamp in judged} == set(log.unique_frames)
    for frame in offline.frames:
        for module, want in frame.results.items():
            got = judged[(module, frame.timestamp_ms)]
            assert (got.result.failed, got.result.skipped) == (want.failed, want.skipped)
            assert metrics_difference(want.metrics, got.result.metrics) is None
            assert not got.incomplete


def test_a_dropped_input_is_reported_incomplete_and_the_verdict_holds(
    ros_env: RosEnv, tmp_path: Path
) -> None:
    log = synthesise("cut_in", "perception", 1)
    params = make_params("corrected")
    run = run_stack_graph(
        ros_env.env,
        tmp_path,
        "cut_in:perception:1",
        {
            "semantics": "corrected",
            "topic_namespace": ros_env.namespace,
            **RUN_FACTS,
            "input_timeout_s": 1.0,
        },
        ["--namespace", ros_env.namespace, "--seed", "5", "--drop", "bboxes:0.02"],
    )
    dropped = set(run.publisher["dropped"]["bboxes"])
    assert len(dropped) == 2
    judged = latest_results(run.results)
    flagged = {stamp for (module, stamp), r in judged.items() if "no bboxes record" in r.incomplete}
    assert flagged == dropped
    [verdict] = run.verdicts
    expected = diagnose(log, params).to_json()
    for key in ("primary_root_cause", "root_causes", "partner_id"):
        assert verdict[key] == expected[key]


def test_an_input_the_stack_never_publishes_makes_its_modules_stale(
    ros_env: RosEnv, tmp_path: Path
) -> None:
    run = run_stack_graph(
        ros_env.env,
        tmp_path,
        "lead_braking:prediction:1",
        {
            "semantics": "reference",
            "topic_namespace": ros_env.namespace,
            **RUN_FACTS,
            "input_timeout_s": 0.5,
        },
        ["--namespace", ros_env.namespace, "--drop", "predictions_with_perception:1.0"],
        after_publisher_s=60.0,
    )
    by_name: dict[str, set[int]] = {}
    for status in run.diagnostics:
        by_name.setdefault(status["name"], set()).add(status["level"])
    stale = 3
    for module in ("prediction", "planning"):  # the reference modules reading it
        assert stale in by_name[f"ads_rca/{module}"]
        messages = [s["message"] for s in run.diagnostics if s["name"] == f"ads_rca/{module}"]
        assert any("no predictions_with_perception input" in m for m in messages)
    for module in ("perception", "controller"):  # they do not read it: judged, never for it
        statuses = [s for s in run.diagnostics if s["name"] == f"ads_rca/{module}"]
        assert any(s["message"].startswith("frame ") for s in statuses)
        assert not any("predictions_with_perception" in s["message"] for s in statuses)


def test_auto_mode_finds_the_stack_with_no_player_on_the_graph(
    ros_env: RosEnv, tmp_path: Path
) -> None:
    """``stack_mode`` auto (the default): no player publishes run/metadata, so the first
    ego odometry message turns both nodes to stack mode; the verdict is diagnose's."""
    log = synthesise("left_turn", "perception", 1)
    run = run_stack_graph(
        ros_env.env,
        tmp_path,
        "left_turn:perception:1",
        {
            "semantics": "reference",
            "topic_namespace": ros_env.namespace,
            "stack_mode": "auto",
            **RUN_FACTS,
            **NO_LOSS,
        },
        ["--namespace", ros_env.namespace, "--seed", "4"],
        after_publisher_s=60.0,
    )
    [verdict] = run.verdicts
    assert verdict["live"]["complete"] is True, verdict["live"]  # nothing lost deciding
    assert same_verdict(verdict, diagnose(log, make_params("reference")).to_json())
    assert "no player on the graph" in run.outputs["monitors"]
    assert "no player on the graph: stack mode" in run.outputs["aggregator"]
