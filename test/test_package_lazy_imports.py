"""A ``diagnose`` run imports only what it needs: what a run does not use is imported lazily.
Each of these costs 0.03 to 0.4 s at start-up, more than judging a short run."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from ads_rca.sources.log.writer import write_run_log
from ads_rca.synth import synthesise

#: Top-level packages a diagnose of a log folder never needs.
UNNEEDED = (
    "aiohttp",
    "concurrent",
    "dask",
    "distributed",
    "matplotlib",
    "mcap",
    "multiprocessing",
    "pyarrow",
    "rclpy",
    "rich",
    "rosbags",
    "scipy",
    "yaml",
    "zenoh",
)


@pytest.mark.parametrize("semantics", ["reference", "corrected"])
def test_diagnose_of_a_log_folder_imports_nothing_it_does_not_use(
    tmp_path: Path, semantics: str
) -> None:
    folder = write_run_log(synthesise("cut_in", "perception", seed=4), tmp_path / "log")
    code = (
        "import json, sys\n"
        "from ads_rca.cli import main\n"
        f"status = main(['diagnose', {str(folder)!r}, '--semantics', {semantics!r},"
        f" '--json', {str(tmp_path / 'v.json')!r}])\n"
        "print(json.dumps([status, sorted({m.split('.')[0] for m in sys.modules})]))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    status, loaded = json.loads(done.stdout.strip().splitlines()[-1])
    assert status == 0
    assert sorted(set(UNNEEDED) & set(loaded)) == []


def test_a_batch_child_imports_nothing_the_worker_did_not(tmp_path: Path) -> None:
    """``ads-rca batch`` forks a child per run from a warmed-up worker: whatever the child
    imports itself it pays for on every run (SciPy's solver alone is 0.4 s)."""
    folder = write_run_log(synthesise("cut_in", "perception", seed=4), tmp_path / "log")
    code = (
        "import json, sys\n"
        "from ads_rca.batch.work import Job, run_job, warm_up\n"
        "from ads_rca.sources.bag.options import BagOptions\n"
        "from ads_rca.params import make_params\n"
        "warm_up()\n"
        "before = set(sys.modules)\n"
        "rows = []\n"
        "for mode in ('reference', 'corrected'):\n"
        f"    job = Job('id', {str(folder)!r}, make_params(mode), 64.0, BagOptions(), 60.0)\n"
        "    rows.append(run_job(job).row.get('error'))\n"
        "new = sorted(set(sys.modules) - before)\n"
        "print(json.dumps([rows, new, 'scipy.optimize' in before]))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    errors, imported, solver_warm = json.loads(done.stdout.strip().splitlines()[-1])
    assert errors == ["", ""]  # diagnosed, no error
    assert imported == []
    assert solver_warm  # a crowded frame's matching (not in this log) needs it


def test_help_imports_no_command_module_and_no_numpy() -> None:
    """``ads-rca --help`` and a mistyped command need the commands' names and help lines
    only: no command's module, nothing of numpy (0.05 s of CPU instead of 0.3 s)."""
    code = (
        "import json, sys\n"
        "from ads_rca.cli import main\n"
        "for argv in (['--help'], ['no-such-command']):\n"
        "    try:\n"
        "        main(argv)\n"
        "    except SystemExit:\n"
        "        pass\n"
        "print(json.dumps(sorted(sys.modules)))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    loaded = json.loads(done.stdout.strip().splitlines()[-1])
    commands = [m for m in loaded if m.startswith("ads_rca.commands.")]
    assert commands == [] and "numpy" not in loaded
    assert "diagnose" in done.stdout and "find the root cause" in done.stdout
