"""Benchmark: peak memory and time of ``ads-rca diagnose`` against boxes per frame and frames.

    python bench/bench_memory.py [--boxes 100 1000 5000 10000] [--frames 1000 10000 100000]
                                 [--actors 2] [--semantics reference corrected] [--workers 1]

Each row is one whole ``ads-rca diagnose --json`` process (its peak resident set and its
CPU time, user + system, from ``wait4``, so the interpreter and libraries are counted; its
wall time), on a log written to ``--dir``:

* boxes: a short ``cruise`` log (20 frames, 5 actors) with one frame holding N detections
  and N ground-truth boxes (random image boxes, each detection a jittered gt box);
* frames: a ``cruise`` log of N frames with ``--actors`` background actors.

``input MB`` is the log's size on disk (file contents). Peak memory should grow linearly in
both and stay within a few times the input (the last column); the boxes rows should stay
near the interpreter's own baseline.
"""

from __future__ import annotations

import argparse
import shutil
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
from timing import Timing, run_child

from ads_rca.model import OPTIONAL_FOLDERS, Boxes, RunLog
from ads_rca.sources.log.writer import write_run_log
from ads_rca.synth import synthesise


def cruise_crashing_at_the_end(frames: int, actors: int) -> RunLog:
    """A cruise log whose last frame is declared the collision frame: the corrected rules
    then judge every frame against a partner (the expensive path)."""
    log = synthesise("cruise", "none", seed=1, frames=frames, actors=actors)
    last = log.frames[-1] // log.frame_ms
    log.metadata = replace(log.metadata, collision_frame=last, total_frames=last)
    return log


def write_boxes_log(folder: Path, boxes: int) -> None:
    """20 cruise frames; the middle one holds ``boxes`` detections and gt boxes."""
    log = cruise_crashing_at_the_end(20, 5)
    rng = np.random.default_rng(0)
    xy = rng.uniform(0, 1920, (boxes, 2))
    gt = np.concatenate([xy, xy + rng.uniform(5, 80, (boxes, 2))], axis=1)
    det = gt + rng.normal(0, 3, gt.shape)
    ids = tuple(str(i) for i in range(boxes))
    extras = tuple({"label": "vehicle"} for _ in range(boxes))
    ts = log.frames[len(log.frames) // 2]
    log.bboxes_gt[ts] = Boxes(ids, gt, extras)
    log.bboxes[ts] = Boxes(ids, det, extras)
    write_run_log(log, folder)


def write_frames_log(folder: Path, frames: int, actors: int) -> None:
    """A cruise log of ``frames`` frames whose last frame is declared the collision."""
    write_run_log(cruise_crashing_at_the_end(frames, actors), folder)


def write_seed_format_log(folder: Path, frames: int, actors: int) -> None:
    """:func:`write_frames_log` of ``actors`` actors, the ego among them, in the seed format
    the reference tool reads: none of our optional folders (``detections_3d/``...), which
    the benches against the reference tool's figures leave out."""
    write_frames_log(folder, frames, actors - 1)
    for optional in OPTIONAL_FOLDERS:
        shutil.rmtree(folder / optional, ignore_errors=True)


def size_on_disk(folder: Path) -> int:
    return sum(p.stat().st_size for p in folder.rglob("*") if p.is_file())


def measure(folder: Path, semantics: str, workers: int) -> tuple[float, Timing]:
    """(peak MB, wall and CPU time) of one ``diagnose --json`` process."""
    command = [sys.executable, "-m", "ads_rca.cli", "diagnose", str(folder)]
    command += ["--semantics", semantics, "--workers", str(workers)]
    command += ["--json", str(folder.with_suffix(".json"))]
    done = run_child(command, capture=False)
    if done.returncode != 0:
        raise SystemExit(f"diagnose failed ({done.returncode}) on {folder}")
    return done.max_rss_mb, done.timing


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--boxes", type=int, nargs="*", default=[100, 1000, 5000, 10_000])
    parser.add_argument("--frames", type=int, nargs="*", default=[1000, 10_000, 100_000])
    parser.add_argument("--actors", type=int, default=2, help="background actors (frames rows)")
    parser.add_argument("--semantics", nargs="+", default=["reference", "corrected"])
    parser.add_argument("--workers", type=int, default=1, help="diagnose --workers")
    parser.add_argument("--dir", default="out/bench_memory", help="where logs are written")
    args = parser.parse_args()

    root = Path(args.dir)
    root.mkdir(parents=True, exist_ok=True)
    print(
        f"diagnose --json, --workers {args.workers}; peak = the process's max RSS; "
        "s = wall, CPU = user + system seconds"
    )
    print(f"{'series':<8}{'N':>8}{'input MB':>10}", end="")
    for semantics in args.semantics:
        name = semantics[:3]
        print(f"{name + ' MB':>10}{name + ' s':>9}{name + ' CPU':>9}{'x input':>9}", end="")
    print()
    jobs = [("boxes", n) for n in args.boxes] + [("frames", n) for n in args.frames]
    for series, n in jobs:
        folder = root / f"{series}-{n}"
        if folder.exists():
            shutil.rmtree(folder)
        if series == "boxes":
            write_boxes_log(folder, n)
        else:
            write_frames_log(folder, n, args.actors)
        input_mb = size_on_disk(folder) / 2**20
        print(f"{series:<8}{n:>8}{input_mb:>10.1f}", end="", flush=True)
        for semantics in args.semantics:
            peak, took = measure(folder, semantics, args.workers)
            print(
                f"{peak:>10.0f}{took.wall_s:>9.1f}{took.cpu_s:>9.1f}{peak / input_mb:>9.1f}",
                end="",
                flush=True,
            )
        print()
        shutil.rmtree(folder)
        folder.with_suffix(".json").unlink(missing_ok=True)


if __name__ == "__main__":
    main()
