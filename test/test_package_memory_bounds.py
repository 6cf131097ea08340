"""Memory stays linear in the input: big frames, block-wise box matching, equality with the
all-pairs versions; the aggregator's memory stays flat."""

from __future__ import annotations

import json
import math
import os
import resource
import subprocess
import sys
import tracemalloc
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from logfactory import make_log
from scipy.optimize import linear_sum_assignment

from ads_rca.diagnosis.engine import diagnose
from ads_rca.diagnosis.verdict import FrameResults, json_safe
from ads_rca.foundation.geometry import axis_aligned_iou
from ads_rca.foundation.strictjson import NONFINITE_KEY
from ads_rca.live.aggregate import AggregatorCore
from ads_rca.live.results import FrameMarker, LiveResult
from ads_rca.model import Boxes
from ads_rca.oracles import reference
from ads_rca.oracles.corrected.perception import match_boxes
from ads_rca.params import make_params
from ads_rca.sources.log.writer import write_run_log
from ads_rca.synth import synthesise

BIG = 3000  # detections and gt boxes in the big frame
#: Address space the big frame may add to a small log's: the all-pairs matching needed
#: several (3000, 3000) float arrays at once (72 MB each), block-wise it needs a few MB.
HEADROOM = 128 << 20


def random_boxes(rng: np.random.Generator, n: int, size: float = 1920.0) -> np.ndarray:
    xy = rng.uniform(0, size, (n, 2))
    wh = rng.uniform(5, 80, (n, 2))
    return np.concatenate([xy, xy + wh], axis=1)


def write_log(folder: Path, boxes: int) -> int:
    """A small valid log; with ``boxes`` > 0, one frame holds that many detections and gt
    boxes (each detection a jittered gt box). Returns that frame's timestamp."""
    log = make_log(6, 4, seed=3)
    ts = log.frames[2]
    if boxes:
        rng = np.random.default_rng(5)
        gt = random_boxes(rng, boxes)
        det = gt + rng.normal(0, 3, gt.shape)
        ids = tuple(str(i) for i in range(boxes))
        extras: tuple[dict[str, object], ...] = tuple({} for _ in range(boxes))
        log.bboxes_gt[ts] = Boxes(ids, gt, extras)
        log.bboxes[ts] = Boxes(ids, det, extras)
    write_run_log(log, folder)
    return ts


def diagnose_limited(folder: Path, semantics: str, limit: int | None) -> tuple[dict[str, Any], int]:
    """``diagnose --json`` in a child, with an address-space limit; (JSON, its VmPeak)."""
    out = folder.with_suffix(f".{semantics}.json")
    # The code a crowd loads (SciPy's optimize and sparse graphs, with their libraries: about
    # 50 MB of address space) is loaded in every run, so the baseline has it too: the
    # headroom is for the big frame's data.
    script = (
        "import sys, resource\n"
        "import scipy.optimize, scipy.sparse.csgraph\n"
        "from ads_rca.cli import main\n"
        "code = main(sys.argv[1:])\n"
        "peak = [l.split()[1] for l in open('/proc/self/status') if l.startswith('VmPeak')]\n"
        "print('VMPEAK', peak[0])\n"
        "sys.exit(code)\n"
    )

    def cap() -> None:
        if limit is not None:
            resource.setrlimit(resource.RLIMIT_AS, (limit, limit))

    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    args = ["diagnose", str(folder), "--semantics", semantics, "--workers", "1", "--json"]
    done = subprocess.run(
        [sys.executable, "-c", script, *args, str(out)],
        check=False,
        capture_output=True,
        text=True,
        env=env,
        preexec_fn=cap,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    peak = next(line.split()[1] for line in done.stdout.splitlines() if "VMPEAK" in line)
    return json.loads(out.read_text()), int(peak) * 1024


@pytest.mark.parametrize("semantics", ["reference", "corrected"])
def test_a_frame_of_3000_by_3000_boxes_fits_in_little_memory(
    tmp_path: Path, semantics: str
) -> None:
    """The all-pairs IoU of one 3000 x 3000 frame ran out of a modest address space; the
    block-wise matching judges it within a small headroom over a small log's needs."""
    write_log(tmp_path / "small", 0)
    _, baseline = diagnose_limited(tmp_path / "small", semantics, None)
    ts = write_log(tmp_path / "big", BIG)
    document, _ = diagnose_limited(tmp_path / "big", semantics, baseline + HEADROOM)
    assert not [p for p in document["input_problems"] if "MemoryError" in p["issue"]]
    frame = next(f for f in document["frames"] if f["timestamp_ms"] == ts)
    perception = frame["perception"]
    assert "skipped" not in perception
    matched = perception["n_matched"] if semantics == "reference" else perception["matched"]
    assert matched > BIG * 0.8


# ------------------------------------------------------------- block-wise == all pairs


def slow_greedy(det: np.ndarray, gt: np.ndarray) -> tuple[list[int], list[int], list[float]]:
    """The spec's greedy matching on the whole IoU matrix, one detection at a time."""
    iou = np.nan_to_num(axis_aligned_iou(det, gt), nan=0.0)
    used: set[int] = set()
    rows: list[int] = []
    cols: list[int] = []
    values: list[float] = []
    for i in range(len(det)):
        best, best_j = 0.0, -1
        for j in range(len(gt)):
            if j not in used and iou[i, j] > best:  # strict: ties keep the earlier gt
                best, best_j = float(iou[i, j]), j
        if best_j >= 0:
            used.add(best_j)
            rows.append(i)
            cols.append(best_j)
            values.append(best)
    return rows, cols, values


coord = st.one_of(
    st.integers(0, 12).map(float),  # integer corners: many exact ties
    st.floats(0, 12, allow_nan=False),
    st.just(math.nan),
)
boxes = st.lists(st.lists(coord, min_size=4, max_size=4), max_size=14)


@settings(max_examples=300, deadline=None)
@given(boxes, boxes, st.sampled_from([1, 2, 5, 16, 1 << 18]))
def test_blockwise_greedy_equals_the_all_pairs_greedy(
    det: list[list[float]], gt: list[list[float]], max_pairs: int
) -> None:
    a = np.array(det, dtype=np.float64).reshape(-1, 4)
    b = np.array(gt, dtype=np.float64).reshape(-1, 4)
    rows, cols, values = reference.greedy_match(a, b, max_pairs=max_pairs)
    want_rows, want_cols, want_values = slow_greedy(a, b)
    assert (rows, cols) == (want_rows, want_cols)
    assert values.tolist() == want_values  # bit for bit


def dense_hungarian(det: np.ndarray, gt: np.ndarray, thr: float) -> tuple[np.ndarray, ...]:
    """The all-pairs matching (the matrix, one assignment)."""
    iou = np.nan_to_num(axis_aligned_iou(det, gt), nan=0.0)
    eligible = iou >= thr
    rows, cols = linear_sum_assignment(np.where(eligible, -iou, 0.0))
    keep = eligible[rows, cols]
    best = iou.max(axis=0) if len(det) else np.zeros(len(gt))
    return rows[keep], cols[keep], iou[rows[keep], cols[keep]], best


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 60), st.integers(0, 60), st.integers(0, 10_000), st.floats(0.05, 0.9))
def test_grouped_hungarian_equals_the_all_pairs_one(n: int, m: int, seed: int, thr: float) -> None:
    """Real-valued boxes (one optimal matching): identical, bit for bit."""
    rng = np.random.default_rng(seed)
    gt = random_boxes(rng, m, size=300.0)
    k = min(n // 2, m)  # jittered copies of gt boxes, then unrelated boxes
    det = np.concatenate([gt[:k] + rng.normal(0, 4, (k, 4)), random_boxes(rng, n - k, 300.0)])
    got = match_boxes(det, gt, thr, dense_pairs=0)
    want = dense_hungarian(det, gt, thr)
    for g, w in zip(got, want, strict=True):
        assert g.tolist() == w.tolist()


@settings(max_examples=300, deadline=None)
@given(boxes, boxes, st.sampled_from([0.1, 0.3, 0.5]))
def test_grouped_hungarian_is_optimal_with_ties(
    det: list[list[float]], gt: list[list[float]], thr: float
) -> None:
    """Integer corners (exact ties): the same total IoU, count and best IoUs; only the
    choice among equally good matchings may differ."""
    a = np.array(det, dtype=np.float64).reshape(-1, 4)
    b = np.array(gt, dtype=np.float64).reshape(-1, 4)
    rows, cols, ious, best = match_boxes(a, b, thr, dense_pairs=0)
    want = dense_hungarian(a, b, thr)
    assert math.isclose(float(ious.sum()), float(want[2].sum()), abs_tol=1e-9)
    assert best.tolist() == want[3].tolist()
    assert len(set(rows.tolist())) == len(rows) and len(set(cols.tolist())) == len(cols)
    assert bool((ious >= thr).all())
    assert rows.tolist() == sorted(rows.tolist())


# -------------------------------------------------------------------------- the aggregator


def feed(core: AggregatorCore, template: list[FrameResults], start: int, stop: int) -> None:
    """Markers and the four results of frames [start, stop), as the monitors send them."""
    for index in range(start, stop):
        stamp = (index + 1) * 50
        core.add_marker(FrameMarker(index, stamp), 0.0)
        for result in template[index % len(template)].results.values():
            moved = LiveResult(index, replace(result, timestamp_ms=stamp), index + 1)
            # Through the wire form, as from a monitor: each result its own objects.
            core.add_result(LiveResult.from_document(moved.to_document()), 0.0)


@pytest.mark.slow
@pytest.mark.parametrize("semantics", ["reference", "corrected"])
def test_the_aggregator_core_retains_little_per_frame(semantics: str) -> None:
    """Results are spilled to disk: from 2,000 to 10,000 frames the core's retained memory
    grows by fixed-size columns only (a few hundred bytes a frame; it held ~8 KB)."""
    params = make_params(semantics)
    log = synthesise("cut_in", "perception", seed=2)
    template = diagnose(log, params).frames
    core = AggregatorCore(params, verdict_timeout_s=1e9)
    core.set_metadata(replace(log.metadata, collision_frame=-1), "test", 0.0)
    tracemalloc.start()
    try:
        feed(core, template, 0, 2000)
        at_2k = tracemalloc.get_traced_memory()[0]
        feed(core, template, 2000, 10_000)
        at_10k = tracemalloc.get_traced_memory()[0]
    finally:
        tracemalloc.stop()
    per_frame = (at_10k - at_2k) / 8000
    assert per_frame < 400, f"{per_frame:.0f} bytes a frame retained"
    core.set_finished(0.0)
    outcome = core.poll(1.0)
    assert outcome is not None
    frames = outcome.document["frames"]
    assert len(frames) == 10_000
    # What was spilled comes back exactly: frame 7000 is the template's frame 7000 % len.
    source = template[7000 % len(template)]
    assert frames[7000]["perception"]["failed"] == source.results["perception"].failed
    metrics = source.results["perception"].metrics
    got = {k: v for k, v in frames[7000]["perception"].items() if k in metrics}
    # The document is the strict contract: NaN is null, named in the top-level annotation.
    want = json_safe(metrics)
    named = want.pop(NONFINITE_KEY, {})
    assert got == want
    annotation = outcome.document.get(NONFINITE_KEY, {})
    for pointer, kind in named.items():
        assert annotation[f"/frames/7000/perception{pointer}"] == kind


def test_the_aggregator_core_drops_an_absurd_index() -> None:
    """A result or marker far beyond every index held is dropped, not allocated for."""
    core = AggregatorCore(make_params("reference"))
    log = synthesise("cut_in", "perception", seed=2)
    result = diagnose(log, make_params("reference")).frames[0].results["perception"]
    core.add_marker(FrameMarker(10**12, 50), 0.0)
    core.add_result(LiveResult(10**12, result, 1), 0.0)
    assert core.expected.count == 0 and core.progress["perception"] == -1
    assert not core.results.has("perception", 10**12)
