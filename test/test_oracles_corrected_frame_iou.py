"""The 2-D perception rule's IoU matrices are computed for a batch of frames at once (the frame
judged and those after it) and cached per frame: each batch member is, bit for bit, the frame
scored alone; a frame whose boxes were replaced since is scored afresh; frames judged backwards
and frames too large to batch are scored alone."""

from __future__ import annotations

import numpy as np

from ads_rca.foundation.geometry import axis_aligned_iou, axis_aligned_ious
from ads_rca.model import Boxes, RunLog, RunMetadata
from ads_rca.oracles.base import RunContext
from ads_rca.oracles.corrected.context import CorrectedContext, corrected_context
from ads_rca.oracles.corrected.perception import FRAME_IOUS, frame_iou
from ads_rca.oracles.frame_iou import BATCH_PAIRS
from ads_rca.params import make_params

TPF = 50


def boxes(corners: list[list[float]] | np.ndarray) -> Boxes:
    array = np.asarray(corners, dtype=np.float64).reshape(-1, 4)
    return Boxes(tuple(str(i) for i in range(len(array))), array, tuple({} for _ in array))


def context(frames: int) -> tuple[RunLog, CorrectedContext]:
    """Frame k: detection (k, 0, k + 2, 2) and a NaN one; gt (k + 1, 0, k + 3, 2)."""
    stamps = tuple(k * TPF for k in range(frames))
    log = RunLog(metadata=RunMetadata(TPF, (1.3, 0.0, 1.8), -1, frames), frames=stamps)
    for k, ts in enumerate(stamps):
        log.bboxes[ts] = boxes([[k, 0, k + 2, 2], [np.nan, 0, 1, 1]])
        log.bboxes_gt[ts] = boxes([[k + 1, 0, k + 3, 2]])
    return log, corrected_context(RunContext.create(log, make_params("corrected", {})))


def test_a_batch_scores_each_frame_as_alone_bit_for_bit() -> None:
    """NaN, infinite, empty, touching (signed zeros) boxes and empty frames included."""
    rng = np.random.default_rng(4)
    with np.errstate(invalid="ignore", divide="ignore"):
        for case in range(600):
            a_sets, b_sets = [], []
            for _frame in range(int(rng.integers(0, 6))):
                n, m = rng.integers(0, 12, size=2)
                a, b = rng.random((n, 4)) * 100, rng.random((m, 4)) * 100
                if case % 2 == 0:
                    a[rng.random((n, 4)) < 0.1] = np.nan
                    b[rng.random((m, 4)) < 0.1] = np.nan
                if case % 3 == 0:  # zero-area boxes
                    a[:, 2] = np.where(rng.random(n) < 0.3, a[:, 0], a[:, 2])
                if case % 5 == 0:  # touching at signed zeros
                    a, b = np.round(a / 50) * 50 - 50, -(np.round(b / 50) * 50 - 50)
                if case % 7 == 0:
                    a[rng.random((n, 4)) < 0.1] = np.inf
                    b[rng.random((m, 4)) < 0.1] = -np.inf
                a_sets.append(a)
                b_sets.append(b)
            for nan_score in (np.nan, 0.0):
                got = axis_aligned_ious(a_sets, b_sets, nan_score)
                assert len(got) == len(a_sets)
                for a, b, iou in zip(a_sets, b_sets, got, strict=True):
                    want = axis_aligned_iou(a, b, nan_score)
                    assert iou.shape == want.shape and iou.tobytes() == want.tobytes(), case


def test_the_first_frame_asked_scores_the_frames_after_it() -> None:
    """Frame 0: the detection (0, 0, 2, 2) and gt (1, 0, 3, 2) overlap 1 x 2 = 2 of a union
    4 + 4 - 2 = 6: IoU 1/3; the NaN detection scores 0. Frames 1 .. 63 are cached too, not
    frame 64 (a batch is 64 frames)."""
    log, judging = context(100)
    iou = frame_iou(judging, 0, log.bboxes[0], log.bboxes_gt[0])
    assert iou is not None and iou.tolist() == [[1 / 3], [0.0]]
    cache = judging.cache(FRAME_IOUS)
    assert cache.lookup(63 * TPF) is not None and cache.lookup(64 * TPF) is None
    cached = frame_iou(judging, 10 * TPF, log.bboxes[10 * TPF], log.bboxes_gt[10 * TPF])
    assert cached is not None and cached.tolist() == [[1 / 3], [0.0]]


def test_a_frame_replaced_since_its_batch_is_scored_afresh() -> None:
    """Frame 5's detection becomes the gt box itself (IoU 1) after frame 0's batch scored it
    (1/3): the new boxes are scored, not the cached matrix."""
    log, judging = context(10)
    frame_iou(judging, 0, log.bboxes[0], log.bboxes_gt[0])
    ts = 5 * TPF
    log.bboxes[ts] = boxes([[6, 0, 8, 2]])
    iou = frame_iou(judging, ts, log.bboxes[ts], log.bboxes_gt[ts])
    assert iou is not None and iou.tolist() == [[1.0]]


def test_a_batch_scores_again_the_frames_cached_for_other_records() -> None:
    """After frame 0's batch, frames 5 and 6 are replaced (each detection becomes its gt box:
    IoU 1): frame 5's batch scores frame 6's new boxes with it (its cached matrix is another
    record's) and stops at frame 7, cached for its very records."""
    log, judging = context(10)
    cache = judging.cache(FRAME_IOUS)
    frame_iou(judging, 0, log.bboxes[0], log.bboxes_gt[0])
    seven = cache.lookup(7 * TPF)
    for k in (5, 6):
        log.bboxes[k * TPF] = boxes([[k + 1, 0, k + 3, 2]])
    frame_iou(judging, 5 * TPF, log.bboxes[5 * TPF], log.bboxes_gt[5 * TPF])
    six = cache.lookup(6 * TPF)
    assert six is not None and six[0] is log.bboxes[6 * TPF] and six[2].tolist() == [[1.0]]
    assert cache.lookup(7 * TPF) is seven


def test_frames_judged_backwards_and_large_frames_are_scored_alone() -> None:
    """A batch stops at a frame already cached (frame 9, then 8 alone) and at a frame with
    more pairs than BATCH_PAIRS (frame 2: frames 0 and 1 only); that frame is not batched."""
    log, judging = context(10)
    cache = judging.cache(FRAME_IOUS)
    frame_iou(judging, 9 * TPF, log.bboxes[9 * TPF], log.bboxes_gt[9 * TPF])
    nine = cache.lookup(9 * TPF)
    frame_iou(judging, 8 * TPF, log.bboxes[8 * TPF], log.bboxes_gt[8 * TPF])
    assert nine is not None and cache.lookup(9 * TPF) is nine  # not scored again
    assert cache.lookup(7 * TPF) is None
    big = boxes(np.tile([2.0, 0.0, 4.0, 2.0], (BATCH_PAIRS + 1, 1)))
    log.bboxes[2 * TPF] = big
    frame_iou(judging, 0, log.bboxes[0], log.bboxes_gt[0])
    assert cache.lookup(TPF) is not None and cache.lookup(2 * TPF) is None
    assert frame_iou(judging, 2 * TPF, big, log.bboxes_gt[2 * TPF]) is None
