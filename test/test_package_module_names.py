"""One name per module everywhere: CLI choices, node names, diagnostics, topics, JSON, text.

The reference tool's output names the modules ``perception``, ``prediction``, ``planning``,
``controller``, and ``reference`` output must match it byte for byte, so those are the names
everywhere: ``synth --fault controller`` (``control`` still accepted), ``controller_monitor``,
``ads_rca/controller`` on ``/diagnostics``, ``metrics/controller``, the JSON's keys and the
table's rows. Parameter names are prefixes (``perc_``, ``pred_``, ``planning_``,
``control_``), not module names, and are not checked here.
"""

from __future__ import annotations

import argparse
import ast
import re
from pathlib import Path

import pytest

from ads_rca.cli import build_parser
from ads_rca.contract import live_topics
from ads_rca.diagnosis.engine import diagnose
from ads_rca.diagnosis.summary import summary_text
from ads_rca.diagnosis.verdict import MODULES
from ads_rca.live import diagnostics
from ads_rca.params import SEMANTICS, make_params
from ads_rca.ros.graph import MONITORS
from ads_rca.sources.registry import open_run
from ads_rca.synth import fault_module, synthesise

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "examples" / "cut_in_perception"
MONITOR_NODE = re.compile(r"\b([a-z]+_monitor)\b")


def synth_fault_action() -> tuple[argparse.ArgumentParser, argparse.Action]:
    parser = build_parser("synth")
    subparsers = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    synth = subparsers.choices["synth"]
    return synth, next(a for a in synth._actions if a.dest == "fault")


def test_synth_fault_choices_are_the_module_names() -> None:
    _, action = synth_fault_action()
    assert action.choices is not None
    assert tuple(action.choices)[:5] == ("none", *MODULES)
    # The rest are variants, named module:variant after the module they blame.
    assert all(c.split(":")[0] in MODULES for c in tuple(action.choices)[5:])
    assert {fault_module(c) for c in action.choices} == {"none", *MODULES}


def test_the_old_fault_spelling_is_an_alias_and_labels_use_the_module_name() -> None:
    synth, _ = synth_fault_action()
    args = synth.parse_args(["out", "--scenario", "lead_braking", "--fault", "control"])
    assert args.fault == "controller"
    assert "{none,perception,prediction,planning,controller," in synth.format_help()
    log = synthesise("lead_braking", "control", 0)
    assert log.metadata.raw["synthesis"]["fault"] == "controller"


def test_monitor_nodes_are_named_after_their_module() -> None:
    assert {f"{module}_monitor": module for module in MODULES} == MONITORS
    assert list(MONITORS.values()) == list(MODULES)


def test_every_monitor_executable_and_mention_is_a_monitor_node() -> None:
    """setup.py's executables exactly; the launch file, README and docs name no other."""
    setup = ast.parse((ROOT / "setup.py").read_text())
    nodes = next(
        node.value
        for node in ast.walk(setup)
        if isinstance(node, ast.Assign) and getattr(node.targets[0], "id", "") == "NODES"
    )
    assert isinstance(nodes, ast.Dict)
    executables = {
        k.value for k in nodes.keys if isinstance(k, ast.Constant) and isinstance(k.value, str)
    }
    assert {e for e in executables if e.endswith("_monitor")} == set(MONITORS)
    texts = [*ROOT.glob("launch_scripts/*.py"), ROOT / "README.md", *ROOT.glob("docs/*.md")]
    for path in texts:
        named = set(MONITOR_NODE.findall(path.read_text()))
        assert named <= set(MONITORS), f"{path.name}: {sorted(named - set(MONITORS))}"


def test_diagnostics_and_topic_names_use_the_module_names() -> None:
    for node, module in MONITORS.items():
        assert node == f"{module}_monitor"
        assert diagnostics.status_name(module) == f"ads_rca/{module}"
        assert diagnostics.heartbeat_name(module) == f"ads_rca/{module}/monitor"
        assert live_topics.metrics_key(module) == f"metrics/{module}"


@pytest.mark.parametrize("semantics", SEMANTICS)
def test_json_keys_and_table_rows_use_the_module_names(semantics: str) -> None:
    document = diagnose(open_run(EXAMPLE), make_params(semantics), workers=1).to_json()
    assert list(document["modules"]) == list(MODULES)
    for frame in document["frames"]:
        assert [k for k in frame if k not in ("frame", "timestamp_ms")] == list(MODULES)
    rows = [line.split()[0] for line in summary_text(document).splitlines()[4:8]]
    assert rows == list(MODULES)
