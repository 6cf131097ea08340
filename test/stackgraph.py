"""Runs stack mode as a user does beside a stack: the ``monitors`` and ``aggregator`` nodes
(stack mode) and the test stack (test/stack_publisher.py), each its own process."""

from __future__ import annotations

import json
import math
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

from golden_outputs import first_difference as _first_difference

from ads_rca.contract.jsontext import dumps_json, loads_json
from ads_rca.diagnosis.engine import Diagnosis, diagnose
from ads_rca.live.results import LiveResult, plain
from ads_rca.model import RunLog
from ads_rca.params import make_params
from ads_rca.ros.graph import AGGREGATOR, GROUP, MONITOR
from ads_rca.ros.launcher import Launcher, ManagedProcess, ParamValue, ros_args
from ads_rca.synth import synthesise

PUBLISHER = Path(__file__).resolve().parent / "stack_publisher.py"
PROBE = Path(__file__).resolve().parent / "diag_probe.py"
#: Monitor parameters the aggregator does not have, and the other way round.
MONITOR_ONLY = frozenset({"history_frames"})
AGGREGATOR_ONLY = frozenset({"stall_timeout_s", "verdict_timeout_s", "detect_collisions"})


@dataclass
class StackRun:
    verdicts: list[dict[str, Any]]
    results: list[LiveResult]  # every result the aggregator received, in order
    publisher: dict[str, Any]  # the test stack's summary line
    diagnostics: list[dict[str, Any]]
    outputs: dict[str, str]


def start_judges(
    launcher: Launcher, diag: Path, monitors: list[str], aggregator: list[str]
) -> tuple[ManagedProcess, ManagedProcess, ManagedProcess]:
    """The diagnostics probe (writing ``diag``), then the ``monitors`` and ``aggregator``
    commands (given whole: their parameters differ per test), started in that order."""
    probe = launcher.start("diag_probe", [sys.executable, str(PROBE), str(diag)])
    return probe, launcher.start("monitors", monitors), launcher.start("aggregator", aggregator)


def run_stack_graph(
    env: dict[str, str],
    tmp: Path,
    synth: str,
    node_params: dict[str, ParamValue],
    publisher_options: Sequence[str] = (),
    params_file: Path | None = None,
    executables: dict[str, list[str]] | None = None,
    after_publisher_s: float = 20.0,
    companions: dict[str, list[str]] | None = None,
) -> StackRun:
    """Monitors and aggregator in stack mode, then the ``companions`` (more of the stack: a
    predictor node...), then the test stack; wait for the verdict. ``synth`` is a
    ``SCENARIO:FAULT:SEED`` spec, or the path of a run the test stack reads (``--log``)."""
    verdict = tmp / "verdict.json"
    metrics = tmp / "metrics.jsonl"
    diag = tmp / "diag.jsonl"
    shared = {"stack_mode": "stack", **node_params}
    agg = {
        **{k: v for k, v in shared.items() if k not in MONITOR_ONLY},
        "verdict_json": str(verdict),
        "metrics_log": str(metrics),
        "exit_after_verdict": True,
    }
    commands = {
        "monitors": [sys.executable, "-m", MONITOR, GROUP],
        "aggregator": [sys.executable, "-m", AGGREGATOR],
        **(executables or {}),
    }
    with Launcher(env, echo=sys.stderr) as launcher:
        watched = {k: v for k, v in shared.items() if k not in AGGREGATOR_ONLY}
        probe, monitors, aggregator = start_judges(
            launcher,
            diag,
            [*commands["monitors"], *ros_args(watched, params_file)],
            [*commands["aggregator"], *ros_args(agg, params_file)],
        )
        started = [launcher.start(name, argv) for name, argv in (companions or {}).items()]
        stack = launcher.start(
            "stack",
            [
                sys.executable,
                str(PUBLISHER),
                "--log" if Path(synth).exists() else "--synth",
                synth,
                *publisher_options,
                "--wait-collision-subscribers",
                "2",  # the monitors' process and the aggregator
            ],
        )
        assert stack.wait(120.0) == 0, stack.output
        code = aggregator.wait(after_publisher_s)
        outputs = {"monitors": monitors.output, "aggregator": aggregator.output}
        assert code == 0, outputs["aggregator"]
        monitors.stop(timeout=10.0)
        for companion in started:
            outputs[companion.name] = companion.output
            companion.stop(timeout=5.0)
        probe.stop(timeout=5.0)
    [summary] = [json.loads(line) for line in stack.lines if line.startswith("{")]
    verdicts = [json.loads(p.read_text()) for p in sorted(tmp.glob("verdict*.json"))]
    results = [
        LiveResult.from_document(loads_json(line))
        for line in metrics.read_text().splitlines()
        if line.strip()
    ]
    statuses = [json.loads(line) for line in diag.read_text().splitlines() if line.strip()]
    return StackRun(verdicts, results, summary, statuses, outputs)


#: The verdict fields a live verdict shares with ``diagnose --json``.
VERDICT_KEYS = (
    "primary_root_cause",
    "root_causes",
    "contributing",
    "partner_id",
    "attribution_basis",
    "modules",
    "modules_judged",
    "evidence",
)


def same_verdict(verdict: dict[str, Any], want: dict[str, Any]) -> bool:
    """Equal verdicts: exact, but the evidence's metrics to 1e-9 (a live view holds fewer
    frames than the whole log, so numpy may sum in another order)."""
    exact = [k for k in VERDICT_KEYS if k != "evidence"]
    return {k: verdict[k] for k in exact} == {k: want[k] for k in exact} and (
        _first_difference(want["evidence"], verdict["evidence"]) is None
    )


def metrics_difference(offline: Mapping[str, Any], live: Mapping[str, Any]) -> str | None:
    """Where a live result's metrics differ from the offline ones (floats to 1e-9, NaN
    equal to NaN; both as they travel: the JSON form), or None."""

    def plain_nan(value: Any) -> Any:
        return "NaN" if isinstance(value, float) and math.isnan(value) else value

    old = json.loads(dumps_json(plain(offline)), parse_constant=lambda c: c)
    new = json.loads(dumps_json(plain(live)), parse_constant=lambda c: c)
    return _first_difference(_map(old, plain_nan), _map(new, plain_nan))


def _map(value: Any, leaf: Any) -> Any:
    if isinstance(value, dict):
        return {k: _map(v, leaf) for k, v in value.items()}
    if isinstance(value, list):
        return [_map(v, leaf) for v in value]
    return leaf(value)


@cache
def crash(scenario: str, fault: str) -> RunLog:
    """A synthesised crash of the grid (seed 1), built once per test process."""
    return synthesise(scenario, fault, 1)


@cache
def offline(scenario: str, fault: str, mode: str) -> Diagnosis:
    """``diagnose`` of :func:`crash` in ``mode``, once."""
    return diagnose(crash(scenario, fault), make_params(mode))


def latest_results(results: list[LiveResult]) -> dict[tuple[str, int], LiveResult]:
    """(module, stamp) → the highest revision received."""
    out: dict[tuple[str, int], LiveResult] = {}
    for result in results:
        key = (result.module, result.stamp_ms)
        if key not in out or result.revision >= out[key].revision:
            out[key] = result
    return out
