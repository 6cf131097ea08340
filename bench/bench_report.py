"""Benchmark: how long ``diagnose --report`` spends on the HTML report; print a table.

    python bench/bench_report.py [--log examples/cut_in_perception] [--repeat 5]

Per mode: the diagnosis once (not timed), then ``render`` (every figure drawn and encoded,
the page built) wall and CPU time, each the best of ``--repeat``, and the page's size. Run it with
``PYTHONPATH`` on an older checkout to compare with that version's report.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from timing import best, timed

import ads_rca
from ads_rca.diagnosis.engine import diagnose
from ads_rca.params import SEMANTICS, make_params
from ads_rca.report.html import render
from ads_rca.sources.registry import open_run

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "cut_in_perception"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--log", type=Path, default=EXAMPLE)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    print(f"report of {args.log} ({Path(ads_rca.__file__).parent}), best of {args.repeat}")
    header = ("semantics", "frames", "wall s", "CPU s", "page KB", "images")
    print(f"{header[0]:<10} " + " ".join(f"{h:>7}" for h in header[1:]))
    for mode in SEMANTICS:
        result = diagnose(open_run(args.log), make_params(mode))
        render(result)  # warm: fonts and matplotlib caches
        runs = [timed(lambda: render(result)) for _ in range(max(args.repeat, 1))]  # noqa: B023
        page, took = runs[-1][0], best(t for _, t in runs)
        print(
            f"{mode:<10} {len(result.frames):>7} {took.wall_s:>7.2f} {took.cpu_s:>7.2f} "
            f"{len(page.encode()) / 1024:>7.0f} {page.count('<img '):>7}"
        )


if __name__ == "__main__":
    main()
