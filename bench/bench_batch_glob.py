"""Benchmark: expanding ``batch 'ROOT/**'`` on a tree with symlink loops; print wall, CPU
and peak RSS.

    python bench/bench_batch_glob.py [--runs 2] [--loops 2] [--limit 30]

The tree: ``--runs`` copies of the bundled example (each a log folder of ~570 entries) and
``--loops`` folders ``loop_i/back -> ..`` (each a way back to ROOT). Measured, each in a
child process of its own (``os.wait4``: its CPU time and peak RSS, also when it is killed):
``glob.glob(ROOT/**, recursive=True)`` as ``batch`` expanded a glob before issue 41 (it
follows every loop until the path is too long: with two loops, 2**40 paths), stopped
after ``--limit`` seconds; and :func:`ads_rca.batch.inputs.expand_inputs` now.
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "examples" / "cut_in_perception"

BEFORE = """
import glob, sys
matches = glob.glob(sys.argv[1], recursive=True)
print(len(matches))
"""
NOW = """
import sys
from ads_rca.batch.inputs import expand_inputs
notes = []
runs = expand_inputs([sys.argv[1]], notes.append)
print(len(runs), *notes, sep="\\n")
"""


def tree(root: Path, runs: int, loops: int) -> None:
    for i in range(runs):
        shutil.copytree(EXAMPLE, root / f"run_{i}")
    for i in range(loops):
        (root / f"loop_{i}").mkdir()
        (root / f"loop_{i}" / "back").symlink_to("..")


def measure(code: str, pattern: str, limit: float) -> tuple[str, float, float, float]:
    """(its output or "stopped", wall s, CPU s, peak RSS MB) of ``code`` run on ``pattern``."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    start = time.perf_counter()
    child = subprocess.Popen(
        [sys.executable, "-c", code, pattern], stdout=subprocess.PIPE, text=True, env=env
    )
    deadline = start + limit
    while True:
        pid, status, usage = os.wait4(child.pid, os.WNOHANG)
        if pid:
            break
        if time.perf_counter() > deadline:
            child.send_signal(signal.SIGKILL)
            pid, status, usage = os.wait4(child.pid, 0)
            break
        time.sleep(0.01)
    wall = time.perf_counter() - start
    child.returncode = os.waitstatus_to_exitcode(status)
    assert child.stdout is not None
    output = child.stdout.read().strip().replace("\n", " | ")
    child.stdout.close()
    if child.returncode == -signal.SIGKILL:
        output = f"still expanding at {limit:g} s (killed)"
    return output, wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--runs", type=int, default=2)
    parser.add_argument("--loops", type=int, default=2)
    parser.add_argument("--limit", type=float, default=30.0, help="seconds before a kill")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) / "root"
        root.mkdir()
        tree(root, args.runs, args.loops)
        pattern = f"{root}/**"
        print(f"tree: {args.runs} runs, {args.loops} loops; pattern ROOT/**")
        print(f"{'expansion':<28} {'wall s':>8} {'CPU s':>8} {'peak RSS MB':>12}  result")
        for name, code in (("glob.glob (before)", BEFORE), ("expand_inputs (now)", NOW)):
            output, wall, cpu, rss = measure(code, pattern, args.limit)
            print(f"{name:<28} {wall:8.2f} {cpu:8.2f} {rss:12.1f}  {output}")


if __name__ == "__main__":
    main()
