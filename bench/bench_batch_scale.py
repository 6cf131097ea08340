"""Benchmark: ``ads-rca batch`` at scale: first-row time, client memory, Ctrl-C to exit.

    python bench/bench_batch_scale.py [--runs 100000 30000] [--workers 2] [--rows 200]
                                      [--after S] [--tree LABEL=PATH ...] [--dir DIR]

    # before and after issue 43's fix, side by side:
    git worktree add --detach /tmp/b43 2cd545f
    python bench/bench_batch_scale.py --tree before=/tmp/b43 after=.
    git worktree remove /tmp/b43

Issue 43: at 100k runs the first row came after ~90 s, the command held 1.7 GB, and
Ctrl-C exited 1 after ~80 s with a traceback and thousands of lines of stderr. Each
``--runs`` size is a paths file of that many cheap runs (empty folders, made once under
``--dir``: each is a row "not an ADS running log" after a fork and a failed open, so the
batch's own cost is what is measured, not diagnosis). For each ``--tree`` (the code a
``PYTHONPATH`` points at: e.g. ``before=/tmp/b43`` a worktree of the old commit, and
``after=.``) the real command runs in its own process group with a local cluster; polled
every 0.1 s:

* **first row**: wall seconds from start to the first row in ``results.csv`` and the CPU
  seconds (user + system) the command and its descendants spent until then;
* **client MB**: the command's own peak resident set (``VmHWM`` in ``/proc/PID/status``,
  last read before it exits): the client, and the local cluster's scheduler, which runs
  in the command's process; the workers are not counted;
* **Ctrl-C**: after ``--rows`` rows the group is sent SIGINT (as a terminal does); wall
  seconds to exit, the CPU spent meanwhile (``wait4``'s total, the command and everything
  it reaped, minus what the command and its live descendants had spent at the signal),
  the exit status, stderr's line count and whether it holds a traceback. A command still
  running 180 s after the signal is killed (status -9).

Measured on 2 cores loaded by other work (load average ~7), 2 workers, Ctrl-C at 200 rows:

    code        runs first row s  (CPU s)  client MB  rows  Ctrl-C s  (CPU s) status  traceback
    before    100000        79.0     39.8       1537   200      62.8     64.5    130        yes
    after     100000         8.1      4.9        137   200       1.9      2.3    130         no
    before     30000        20.8     12.4        526   200      13.1     14.6    130        yes
    after      30000         5.0      2.8        117   200       1.1      2.1    130         no
    before       100         3.2      1.9        104    52       1.1      0.9    130         no
    after        100         3.4      2.0        103    51       1.1      0.9    130         no
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import psutil
from timing import load_average

REPO = Path(__file__).resolve().parents[1]
#: Seconds allowed from start to the ``--rows``-th row, and from Ctrl-C to exit.
START_LIMIT = 600.0
EXIT_LIMIT = 180.0


def cheap_runs(root: Path, n: int) -> Path:
    """A paths file of ``n`` empty run folders (made once, reused)."""
    folder = root / f"runs_{n}"
    listing = root / f"paths_{n}.txt"
    if not listing.exists():
        folder.mkdir(parents=True, exist_ok=True)
        names = [f"r{i:06d}" for i in range(n)]
        for name in names:
            (folder / name).mkdir(exist_ok=True)
        listing.write_text("".join(f"{folder / name}\n" for name in names))
    return listing


def _rows(csv: Path) -> int:
    try:
        with csv.open("rb") as handle:
            return max(0, handle.read().count(b"\n") - 1)
    except FileNotFoundError:
        return 0


def _hwm_mb(pid: int) -> float:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return float("nan")


def _tree_cpu_s(pid: int) -> float:
    """CPU of ``pid`` (with the children it reaped) and of its live descendants."""
    try:
        root = psutil.Process(pid)
        times = root.cpu_times()
        total = times.user + times.system + times.children_user + times.children_system
        for child in root.children(recursive=True):
            try:
                t = child.cpu_times()
                total += t.user + t.system
            except psutil.Error:
                pass
        return float(total)
    except psutil.Error:
        return float("nan")


@dataclass
class Figures:
    first_row_s: float = float("nan")
    first_row_cpu_s: float = float("nan")
    client_mb: float = 0.0
    rows_at_signal: int = 0
    exit_s: float = float("nan")
    exit_cpu_s: float = float("nan")
    status: int = 0
    stderr_lines: int = 0
    traceback: bool = False


def measure(tree: Path, listing: Path, out: Path, workers: int, rows: int, after: float) -> Figures:
    env = dict(os.environ, PYTHONPATH=str(tree), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    argv = [sys.executable, "-m", "ads_rca.cli", "batch", str(listing), "--out", str(out)]
    figures = Figures()
    with tempfile.TemporaryFile() as err:
        start = time.perf_counter()
        child = subprocess.Popen(
            [*argv, "--workers", str(workers)],
            stdout=subprocess.DEVNULL,
            stderr=err,
            env=env,
            cwd=tree,  # `python -m` puts the working folder first on the path
            start_new_session=True,  # a group of its own: SIGINT to it, as a terminal does
        )
        csv = out / "results.csv"
        signalled = 0.0
        cpu_at_signal = 0.0
        while True:
            pid, status, usage = os.wait4(child.pid, os.WNOHANG)
            if pid:
                break
            now = time.perf_counter()
            peak = _hwm_mb(child.pid)
            if not math.isnan(peak):  # the process is still there
                figures.client_mb = max(figures.client_mb, peak)
            done = _rows(csv)
            if done and figures.first_row_s != figures.first_row_s:
                figures.first_row_s = now - start
                figures.first_row_cpu_s = _tree_cpu_s(child.pid)
            if not signalled and (
                (done >= rows and now - start >= after) or now - start > START_LIMIT
            ):
                cpu_at_signal = _tree_cpu_s(child.pid)
                figures.rows_at_signal = done
                signalled = time.perf_counter()
                os.killpg(child.pid, signal.SIGINT)
            if signalled and now - signalled > EXIT_LIMIT:
                os.killpg(child.pid, signal.SIGKILL)
            time.sleep(0.1)
        ended = time.perf_counter()
        total_cpu = usage.ru_utime + usage.ru_stime
        figures.status = os.waitstatus_to_exitcode(status)
        if signalled:
            figures.exit_s = ended - signalled
            figures.exit_cpu_s = total_cpu - cpu_at_signal
        with contextlib.suppress(ProcessLookupError):
            os.killpg(child.pid, signal.SIGKILL)  # anything left behind
        err.seek(0)
        text = err.read().decode(errors="replace")
    figures.stderr_lines = text.count("\n")
    figures.traceback = "Traceback" in text
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", type=int, nargs="+", default=[100_000, 30_000])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--rows", type=int, default=200, help="rows before Ctrl-C")
    parser.add_argument(
        "--after", type=float, default=0.0, help="and at least these seconds before Ctrl-C"
    )
    parser.add_argument(
        "--tree", nargs="+", default=[f"after={REPO}"], help="LABEL=PATH: the code to run"
    )
    parser.add_argument(
        "--dir", type=Path, default=Path(tempfile.gettempdir()) / "ads_rca_bench_batch_scale"
    )
    args = parser.parse_args()
    # The command keeps an ignored SIGINT ignored (a bench started in the background):
    # its Ctrl-C is what is measured, so it starts with SIGINT's default action.
    signal.signal(signal.SIGINT, signal.default_int_handler)
    print(
        f"load average {load_average()}; {args.workers} workers; "
        f"Ctrl-C after {args.rows} rows and {args.after:g} s"
    )
    print(
        f"{'code':<8}{'runs':>8}{'first row s':>12}{'(CPU s)':>9}{'client MB':>11}"
        f"{'rows':>6}{'Ctrl-C s':>10}{'(CPU s)':>9}{'status':>7}{'stderr':>8}{'traceback':>10}"
    )
    for n in args.runs:
        listing = cheap_runs(args.dir, n)
        for tree in args.tree:
            label, _, path = tree.partition("=")
            out = args.dir / f"out_{label}_{n}"
            subprocess.run(["rm", "-rf", str(out)], check=True)
            f = measure(
                Path(path).resolve(), listing, out, args.workers, min(args.rows, n // 2), args.after
            )
            print(
                f"{label:<8}{n:>8}{f.first_row_s:>12.1f}{f.first_row_cpu_s:>9.1f}"
                f"{f.client_mb:>11.0f}{f.rows_at_signal:>6}{f.exit_s:>10.1f}{f.exit_cpu_s:>9.1f}"
                f"{f.status:>7}{f.stderr_lines:>8}{'yes' if f.traceback else 'no':>10}",
                flush=True,
            )
            subprocess.run(["rm", "-rf", str(out)], check=True)


if __name__ == "__main__":
    main()
