"""Benchmark: peak memory and time of reading a Dragon Lake Parking scene, streamed.

    python bench/bench_dlp.py [--frames 10000 100000] [--agents 10] [--dir out/bench_dlp]

For each size a synthesised scene (test/writers/dlp_scenes.py: the three scripted agents,
``--agents - 3`` more cars, one parked car) of N frames is written to ``--dir``, so it holds
about N x agents instances. Each measurement is one process (its peak resident set and CPU
time, user + system, from ``wait4``: the interpreter and libraries are counted; its wall
time):

* ``stream``: ``open_run`` of the scene, the instances and frames files streamed
  (ads_rca/sources/json_stream.py) into typed arrays, then the per-frame model built;
* ``json.load``: only ``json.load`` of the instances file, what reading it whole costs
  before any model is built (the naive way, for comparison).

``inst. MB`` is the instances file's size. Streaming should hold memory near the model's own
size, well below the file's Python objects. Figures: docs/performance.md
(``bench/performance.py`` regenerates it).
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

from timing import Timing, run_child

# The dataset writers live with the tests (not in the installed package).
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "test"))

from writers.dlp_scenes import STEM, write_dlp_scene

STREAM = (
    "from ads_rca.sources.registry import open_run; import sys; log = open_run(sys.argv[1]); "
    "print(len(log.frames))"
)
WHOLE = "import json, sys; d = json.load(open(sys.argv[1])); print(len(d))"


def measure(code: str, path: Path) -> tuple[float, Timing]:
    """(peak MB, wall and CPU time) of one process running ``code`` on ``path``."""
    done = run_child([sys.executable, "-c", code, str(path)])
    if done.returncode != 0:
        raise SystemExit(f"failed on {path}: {done.stderr.strip()[-500:]}")
    return done.max_rss_mb, done.timing


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--frames", type=int, nargs="+", default=[10_000, 100_000])
    parser.add_argument("--agents", type=int, default=10, help="moving agents (at least 3)")
    parser.add_argument("--dir", default="out/bench_dlp", help="where scenes are written")
    args = parser.parse_args()
    root = Path(args.dir)
    print("peak = the process's max RSS (MB); s = wall seconds; CPU = user + system seconds")
    print(
        f"{'frames':>8}{'instances':>11}{'inst. MB':>10}{'stream MB':>11}{'stream s':>10}"
        f"{'stream CPU':>12}{'json.load MB':>14}{'json.load s':>13}{'json.load CPU':>15}"
    )
    for frames in args.frames:
        folder = root / f"scene-{frames}"
        if folder.exists():
            shutil.rmtree(folder)
        scene = write_dlp_scene(folder, frames, extra_agents=max(args.agents - 3, 0))
        instances = folder / f"{STEM}_instances.json"
        count = frames * args.agents  # about: two scripted agents live part of the scene
        size = instances.stat().st_size / 2**20
        stream_mb, stream = measure(STREAM, scene)
        whole_mb, whole = measure(WHOLE, instances)
        print(
            f"{frames:>8}{count:>11}{size:>10.0f}{stream_mb:>11.0f}{stream.wall_s:>10.1f}"
            f"{stream.cpu_s:>12.1f}{whole_mb:>14.0f}{whole.wall_s:>13.1f}{whole.cpu_s:>15.1f}",
            flush=True,
        )
        shutil.rmtree(folder)


if __name__ == "__main__":
    main()
