"""Benchmark: reading an atmaCup #18 table of the competition's size, and scoring it.

    python bench/bench_atmacup.py [--rows 43371] [--dir out/bench_atmacup] [--rounds 3]

A synthesised train table (test/writers/atmacup_tables.py ``big_table``: scenes of 40
rows, a green light on every other row, an empty list on the rest) of ``--rows`` rows is
written to ``--dir`` with one traffic-light file per row, and a submission of every row.
Each phase is timed in this process, wall and CPU time each the median of ``--rounds``
rounds:

* ``table only``: ``open_run`` of the CSV with no ``traffic_lights/`` beside it (the
  columns parsed by numpy, the per-row records built);
* ``table + lights``: the same with one traffic-light JSON file per row;
* ``+ submission``: the same with ``--submission`` (the 18 columns, matched by row order);
* ``scores``: ``trajectory_scores`` over every row (MAE, ADE, FDE, per horizon, worst);
* ``diagnose``: judging every frame (``corrected``, every module not judged) and building
  the verdict document with its scores.

Figures: docs/performance.md (``bench/performance.py`` regenerates it).
"""

from __future__ import annotations

import argparse
import shutil
import sys
from collections.abc import Callable
from pathlib import Path

from timing import Timing, median, repeated

# The dataset writers live with the tests (not in the installed package).
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "test"))

from writers.atmacup_tables import TRAIN, big_table, write_submission, write_table

from ads_rca.diagnosis.engine import diagnose
from ads_rca.model import RunLog
from ads_rca.params import make_params
from ads_rca.sources.atmacup.trajectory_scores import trajectory_scores
from ads_rca.sources.formats import SourceOptions
from ads_rca.sources.registry import open_run


def timed(rounds: int, work: Callable[[], object]) -> Timing:
    return median(repeated(work, rounds))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=43_371)
    parser.add_argument("--dir", type=Path, default=Path("out/bench_atmacup"))
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    shutil.rmtree(args.dir, ignore_errors=True)
    rows = big_table(args.rows, lights_every=2)
    bare = write_table(args.dir / "bare", rows, lights=False)
    full = write_table(args.dir / "full", rows)
    submission = write_submission(args.dir / "submission.csv", [r.path for r in rows])
    with_sub = SourceOptions(submission=str(submission))
    log: list[RunLog] = []

    def read_scored() -> None:
        log[:] = [open_run(full, source=with_sub)]

    phases: list[tuple[str, Timing]] = [
        ("table only", timed(args.rounds, lambda: open_run(bare))),
        ("table + lights", timed(args.rounds, lambda: open_run(full))),
        ("+ submission", timed(args.rounds, read_scored)),
    ]
    snapshots = log[0].ego_snapshots
    assert snapshots is not None
    phases.append(("scores", timed(args.rounds, lambda: trajectory_scores(snapshots))))
    params = make_params("corrected")
    phases.append(("diagnose", timed(1, lambda: diagnose(log[0], params).to_json())))
    size = (args.dir / "full" / TRAIN).stat().st_size / 2**20
    print(f"{args.rows} rows, {size:.1f} MB CSV")
    print(f"{'phase':<16}{'rows':>8}{'wall s':>10}{'CPU s':>10}")
    for name, took in phases:
        print(f"{name:<16}{args.rows:>8}{took.wall_s:>10.3g}{took.cpu_s:>10.3g}")


if __name__ == "__main__":
    main()
