"""The Semantics object: the only place a mode's rules live, found by one registry.

The engine and the live nodes must ask the mode's :class:`Semantics` instead of comparing
``params.semantics`` with a mode's name: a comparison elsewhere is a rule written twice
(and a third mode would have to find every one). Only the parameter and CLI layers, which
turn names into parameters, may name a mode.
"""

from __future__ import annotations

import re
import subprocess
import sys
import types
from dataclasses import replace
from pathlib import Path
from typing import Any, cast

import pytest

import ads_rca
from ads_rca.diagnosis.engine import diagnose
from ads_rca.live.window import MonitorCore
from ads_rca.model import ALL_FOLDERS, FOLDERS
from ads_rca.oracles import semantics as registry
from ads_rca.oracles.base import MODULES
from ads_rca.oracles.corrected import CorrectedSemantics
from ads_rca.oracles.semantics import semantics_for
from ads_rca.params import SEMANTICS, make_params
from ads_rca.synth import synthesise

PACKAGE = Path(ads_rca.__file__).resolve().parent
#: Where a mode may be named: parameters and command-line options.
ALLOWED = ("params.py", "commands/", "ros/nodeparams.py")

_NAME = "|".join(SEMANTICS)
#: ``semantics ==``/``!=``, ``== "reference"``, ``"corrected" !=``, ``in ("reference", ...``,
#: ``match ... case "reference"``, ``X[....semantics]`` (a table keyed by the mode's name).
BRANCH = re.compile(
    rf"""semantics\s*[!=]=|[!=]=\s*["']({_NAME})["']|["']({_NAME})["']\s*[!=]="""
    rf"""|\bin\s*[(\[{{]\s*["']({_NAME})["']|case\s+["']({_NAME})["']|\[[\w.]*semantics\]"""
)


def semantics_branches(root: Path) -> list[str]:
    """``file:line: text`` of every comparison with a mode's name outside :data:`ALLOWED`."""
    found = []
    for path in sorted(root.rglob("*.py")):
        relative = path.relative_to(root).as_posix()
        if relative.startswith(ALLOWED):
            continue
        for number, line in enumerate(path.read_text().splitlines(), 1):
            if BRANCH.search(line.split("#", 1)[0]):
                found.append(f"{relative}:{number}: {line.strip()}")
    return found


def test_no_code_outside_the_parameter_layers_branches_on_the_mode_name() -> None:
    branches = semantics_branches(PACKAGE)
    assert not branches, "ask the mode's Semantics instead:\n" + "\n".join(branches)


def test_the_pattern_finds_the_branches_it_forbids(tmp_path: Path) -> None:
    (tmp_path / "diagnosis").mkdir()
    (tmp_path / "diagnosis/engine.py").write_text(
        'if params.semantics == "reference":\n'
        'x = a if "corrected" != mode else b\n'
        'y = mode in ("reference", "corrected")\n'
        "z = TABLE[result.params.semantics]\n"
        'ok = "reference counts"  # a basis text, not a comparison\n'
    )
    (tmp_path / "params.py").write_text('if semantics == "reference":\n')
    assert [b.split(":")[1] for b in semantics_branches(tmp_path)] == ["1", "2", "3", "4"]


def test_every_mode_has_one_registered_semantics_with_its_four_oracles() -> None:
    assert tuple(registry.MODES) == SEMANTICS
    for name in SEMANTICS:
        sem = semantics_for(name)
        assert sem is semantics_for(make_params(name))
        assert sem.name == name
        assert tuple(sem.oracles) == MODULES
        assert set(sem.headline) == set(MODULES)
        for module in MODULES:
            assert set(sem.folders(module)) <= set(ALL_FOLDERS)


def test_the_modes_rules() -> None:
    reference, corrected = semantics_for("reference"), semantics_for("corrected")
    reference_params, corrected_params = make_params("reference"), make_params("corrected")
    # analysed frames: a duplicated timestamp once per file (reference) or once.
    assert reference.analyses(duplicate=True) and not corrected.analyses(duplicate=True)
    assert reference.analyses(duplicate=False) and corrected.analyses(duplicate=False)
    # the effective window: reference counts frames; corrected at least window_s (1 s).
    assert reference.window_frames(reference_params, 50) == 10
    assert corrected.window_frames(corrected_params, 50) == 20
    assert corrected.window_frames(corrected_params, 25) == 40
    # folders read and the look-ahead needed at a frame.
    assert reference.module_folders(["perception"]) == ("bboxes", "bboxes_gt")
    assert corrected.module_folders(["perception"]) == (
        *FOLDERS,
        "detections_3d",
        "tracks_3d",
        "lanes",
        "lanes_predicted",
    )
    assert corrected.module_folders(["controller"]) == FOLDERS
    none: dict[str, dict[int, Any]] = {"predictions_with_perception": {}}
    assert [reference.lookahead_frames(m, reference_params, none, 0, 100) for m in MODULES] == [
        0,
        0,
        0,
        1,
    ]
    assert corrected.modules_lookahead(["perception"], corrected_params, none, 0, 100) == 10
    assert [reference.reads_ego(m) for m in MODULES] == [False, True, True, False]
    assert reference.uses_partner is False and corrected.uses_partner is True
    # the window, the noise floors' frames before its first frame (W + 3 s), control, slack
    assert corrected.rejudge_history(corrected_params, 50) == 20 + (20 + 60) + 10 + 5


class _ThirdSemantics(CorrectedSemantics):
    """A new mode: corrected's oracles, but every file's frame judged."""

    name = "third"
    analyses_duplicates = True


def test_a_third_mode_is_one_module_and_one_registry_entry(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    module = types.ModuleType("third_mode")
    # a module made at run time: its attributes are unknown to the checker
    module.SEMANTICS = _ThirdSemantics()  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "third_mode", module)
    monkeypatch.setitem(registry.MODES, "third", "third_mode")
    params = replace(make_params("corrected"), semantics=cast(Any, "third"))
    assert semantics_for(params) is module.SEMANTICS
    log = synthesise("cut_in", "perception", 1)
    log = replace(log, frames=(*log.frames[:3], log.frames[2], *log.frames[3:]))
    third = diagnose(log, params)
    assert len(third.frames) == len(log.frames)  # the duplicate judged again
    assert len(diagnose(log, make_params("corrected")).frames) == len(log.frames) - 1
    assert third.attribution.primary_root_cause == "perception"
    core = MonitorCore(MODULES, params)
    assert core.semantics is module.SEMANTICS
    assert core.folders == module.SEMANTICS.module_folders(MODULES)


def test_the_verdict_types_do_not_import_the_oracles() -> None:
    """diagnosis/verdict.py holds the types; the modes' attributions (in oracles/) fill them."""
    code = (
        "import sys, ads_rca.diagnosis.verdict; "
        "print(sorted(m for m in sys.modules if 'oracles' in m))"
    )
    loaded = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    assert loaded.strip() == "[]"


def test_each_mode_declares_the_parameters_it_reads_and_its_oracles_report() -> None:
    """One list per mode (``Semantics.parameters``, the outputs' ``thresholds``) and one
    per oracle (``Semantics.reported``), which the oracles' results use as written."""
    fields = set(vars(make_params("corrected")))
    for name in SEMANTICS:
        sem, params = semantics_for(name), make_params(name)
        assert len(set(sem.parameters)) == len(sem.parameters)
        assert set(sem.parameters) <= fields - {"semantics"}
        assert tuple(sem.reported) == MODULES
        for module in MODULES:
            assert set(sem.reported[module]) <= set(sem.parameters), (name, module)
        found = diagnose(synthesise("cut_in", "perception", 1), params)
        assert list(found.to_json(include_frames=False)["thresholds"]) == list(sem.parameters)
        for frame in found.frames:
            for module, result in frame.results.items():
                names = sem.reported[module]
                assert tuple(result.thresholds)[: len(names)] == names
                assert all(result.thresholds[n] == getattr(params, n) for n in names)
