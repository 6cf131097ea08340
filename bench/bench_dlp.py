"""Benchmark: peak memory and time of reading a Dragon Lake Parking scene, streamed.

    python bench/bench_dlp.py [--frames 10000 100000] [--agents 10] [--dir out/bench_dlp]

For each size a synthesised scene (test/writers/dlp_scenes.py: the three scripted agents,
``--agents - 3`` more cars, one parked car) of N frames is written to ``--dir``, so it holds
about N x agents instances. Each row is one process (its peak resident set from ``wait4``:
the interpreter and libraries are counted):

* ``stream``: ``open_run`` of the scene, the instances and frames files streamed
  (ads_rca/sources/json_stream.py) into typed arrays, then the per-frame model built;
* ``json.load``: only ``json.load`` of the instances file, what reading it whole costs
  before any model is built (the naive way, for comparison).

``inst. MB`` is the instances file's size. Streaming should hold memory near the model's own
size, well below the file's Python objects. Measured on the 2-core machine of the issue:

      frames  instances  inst. MB  stream MB  stream s  json.load MB  json.load s
       10000     100000        39         57       0.8           169          0.5
      100000    1000000       390        328       8.4          1581          6.3
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

# The dataset writers live with the tests (not in the installed package).
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "test"))

from writers.dlp_scenes import STEM, write_dlp_scene

STREAM = (
    "from ads_rca.sources.registry import open_run; import sys; log = open_run(sys.argv[1]); "
    "print(len(log.frames))"
)
WHOLE = "import json, sys; d = json.load(open(sys.argv[1])); print(len(d))"


def measure(code: str, path: Path) -> tuple[float, float]:
    """(peak MB, seconds) of one process running ``code`` on ``path``."""
    start = time.perf_counter()
    child = subprocess.Popen([sys.executable, "-c", code, str(path)], stdout=subprocess.DEVNULL)
    _pid, status, usage = os.wait4(child.pid, 0)
    seconds = time.perf_counter() - start
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"failed on {path}")
    return usage.ru_maxrss / 1024, seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--frames", type=int, nargs="+", default=[10_000, 100_000])
    parser.add_argument("--agents", type=int, default=10, help="moving agents (at least 3)")
    parser.add_argument("--dir", default="out/bench_dlp", help="where scenes are written")
    args = parser.parse_args()
    root = Path(args.dir)
    print("peak = the process's max RSS (MB); s = wall seconds")
    print(
        f"{'frames':>8}{'instances':>11}{'inst. MB':>10}{'stream MB':>11}{'stream s':>10}"
        f"{'json.load MB':>14}{'json.load s':>13}"
    )
    for frames in args.frames:
        folder = root / f"scene-{frames}"
        if folder.exists():
            shutil.rmtree(folder)
        scene = write_dlp_scene(folder, frames, extra_agents=max(args.agents - 3, 0))
        instances = folder / f"{STEM}_instances.json"
        count = frames * args.agents  # about: two scripted agents live part of the scene
        size = instances.stat().st_size / 2**20
        stream_mb, stream_s = measure(STREAM, scene)
        whole_mb, whole_s = measure(WHOLE, instances)
        print(
            f"{frames:>8}{count:>11}{size:>10.0f}{stream_mb:>11.0f}{stream_s:>10.1f}"
            f"{whole_mb:>14.0f}{whole_s:>13.1f}",
            flush=True,
        )
        shutil.rmtree(folder)


if __name__ == "__main__":
    main()
