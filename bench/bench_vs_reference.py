"""Benchmark: one whole ``ads-rca diagnose`` process against the reference tool, side by side.

    python bench/bench_vs_reference.py [--reference DIR --reference-python PY]
                                       [--sizes 1957x11 10000x50] [--repeat 5] [--dir out/bench]

For each size FRAMESxACTORS a ``cruise`` log of that many frames and actors (the ego and
ACTORS - 1 background actors; its last frame declared the collision frame, so the corrected
rules judge every frame against a partner) is written under ``--dir`` in the seed format's
seven folders (the synthesiser's 3-D and control folders removed: the reference reads
none). Then, in turn, one run each of: the reference tool (``PY DIR/main.py
log_dir=LOG``, in a scratch working directory, which its configuration framework writes
into), ``ads-rca diagnose LOG --semantics reference --json FILE`` and the same with
``--semantics corrected``; that round is repeated ``--repeat`` times after one warm-up round
(the logs are then in the file cache), and each command's median wall time and median CPU
time (user + system from ``wait4``: the process and the workers it forked) are printed with
the reference tool's wall time divided by ours. Both run with their bytecode cached, as
installed tools do (PYTHONDONTWRITEBYTECODE is cleared for them; the warm-up round writes
it). Without ``--reference`` (the reference tool is not part of this project) only our two
commands are timed.

The 1,957-frame, 11-actor log is the size of issue #18's measurement (13,700 JSON files);
the 10,000-frame, 50-actor log is its second target (under 10 s on 2 cores). Figures:
docs/performance.md (``bench/performance.py`` regenerates it). To measure a change to ours
alone, run this on the commit before and after it, alternating, on the same machine.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from bench_memory import size_on_disk, write_seed_format_log
from timing import Timing, run_child

DEFAULT_SIZES = ("1957x11", "10000x50")
#: Both tools run as installed ones do: with their modules' bytecode cached (written by the
#: warm-up round), whatever PYTHONDONTWRITEBYTECODE says here.
AS_INSTALLED = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


@dataclass
class Command:
    """One command to time, and its wall and CPU times."""

    name: str
    argv: list[str]
    cwd: Path
    times: list[Timing] = field(default_factory=list)
    failed: str = ""

    def run(self, counted: bool) -> None:
        if self.failed:
            return
        done = run_child(self.argv, cwd=self.cwd, env=AS_INSTALLED)
        if done.returncode != 0:
            tail = done.stderr.strip().splitlines()[-1:]
            self.failed = f"exit {done.returncode}: {' '.join(tail)[:120]}"
        elif counted:
            self.times.append(done.timing)

    @property
    def median(self) -> float | None:
        """The median wall time (s), None when the command failed or was not counted."""
        if not self.times or self.failed:
            return None
        return statistics.median(t.wall_s for t in self.times)

    @property
    def median_cpu(self) -> float:
        return statistics.median(t.cpu_s for t in self.times)


def parse_size(text: str) -> tuple[int, int]:
    frames, _, actors = text.partition("x")
    if not (frames.isdigit() and actors.isdigit() and int(actors) >= 1):
        raise argparse.ArgumentTypeError(f"{text!r} is not FRAMESxACTORS (e.g. 1957x11)")
    return int(frames), int(actors)


def commands(log: Path, scratch: Path, args: argparse.Namespace) -> list[Command]:
    """The reference tool (when given) and our two modes on ``log``."""
    found: list[Command] = []
    if args.reference:
        main_py = str(Path(args.reference).resolve() / "main.py")
        python = args.reference_python or sys.executable
        found.append(Command("reference tool", [python, main_py, f"log_dir={log}"], scratch))
    for mode in ("reference", "corrected"):
        argv = [sys.executable, "-m", "ads_rca.cli", "diagnose", str(log), "--semantics", mode]
        argv += ["--json", str(scratch / f"{mode}.json")]
        found.append(Command(f"ads-rca {mode}", argv, scratch))
    return found


def one_size(frames: int, actors: int, args: argparse.Namespace) -> list[str]:
    """Write one log, time every command on it; the table's rows for it."""
    # Absolute: the commands run in the scratch folder.
    with tempfile.TemporaryDirectory(dir=Path(args.dir).resolve()) as tmp:
        log = Path(tmp) / f"cruise_{frames}x{actors}"
        write_seed_format_log(log, frames, actors)
        files = sum(1 for _ in log.rglob("*.json"))
        megabytes = size_on_disk(log) / 1e6
        scratch = Path(tmp) / "scratch"
        scratch.mkdir()
        timed = commands(log, scratch, args)
        for round_ in range(args.repeat + 1):  # round 0 warms the file cache
            for command in timed:
                command.run(counted=round_ > 0)
    reference = timed[0].median if args.reference else None
    rows = []
    for command in timed:
        label = f"{frames}x{actors} ({files} files, {megabytes:.0f} MB)"
        if command.median is None:
            rows.append(f"{label:<32}{command.name:<18}{'failed':>9}  {command.failed}")
            continue
        walls = [t.wall_s for t in command.times]
        spread = f"{min(walls):.2f}-{max(walls):.2f}"
        ratio = ""
        if reference is not None and command is not timed[0]:
            ratio = f"{reference / command.median:.1f}x"
        rows.append(
            f"{label:<32}{command.name:<18}{command.median:>9.2f}{spread:>13}"
            f"{command.median_cpu:>9.2f}{ratio:>9}"
        )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawTextHelpFormatter
    )
    parser.add_argument("--reference", help="a checkout of the reference tool (its main.py)")
    parser.add_argument(
        "--reference-python", help="the interpreter with its dependencies (default: this one)"
    )
    parser.add_argument("--sizes", nargs="+", type=parse_size, default=None)
    parser.add_argument("--repeat", type=int, default=5, help="counted rounds (median)")
    parser.add_argument("--dir", default="out/bench", help="where the logs are written")
    args = parser.parse_args()
    sizes = args.sizes or [parse_size(s) for s in DEFAULT_SIZES]
    Path(args.dir).mkdir(parents=True, exist_ok=True)
    print(
        f"whole processes, wall and CPU (user + system) time: medians of {args.repeat} rounds "
        f"after a warm-up; {os.cpu_count()} CPUs; ratio = reference tool / ours (wall)"
    )
    if not args.reference:
        print("reference tool: not given (--reference DIR --reference-python PY); ours only")
    print(f"{'log':<32}{'command':<18}{'median s':>9}{'min-max s':>13}{'CPU s':>9}{'ratio':>9}")
    for frames, actors in sizes:
        for row in one_size(frames, actors, args):
            print(row, flush=True)


if __name__ == "__main__":
    main()
