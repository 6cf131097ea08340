"""The reference perception oracle's match scores, computed for a batch of frames at once,
give every frame the matches its own scores give, on hostile boxes too.

Why: ``frame_match_scores`` replaces each frame's fifteen numpy calls by a share of one batch
(axis_aligned_ious, then what is not above 0 set to 0); a difference in one float, or in
which frames a batch reuses, would change a reference-mode verdict that users compare with
the reference tool's.
"""

from __future__ import annotations

import math
import random

import numpy as np
import pytest
from oraclefixtures import LogBuilder, context, make_boxes

from ads_rca.model import Boxes, RunLog
from ads_rca.oracles.cache import LRU
from ads_rca.oracles.frame_iou import IOU_BATCH
from ads_rca.oracles.reference import oracles
from ads_rca.oracles.reference.oracles import (
    _match_scores,
    frame_match_scores,
    greedy_match,
    judge_perception,
    perception,
)

#: Coordinates a box may have: ordinary, swapped corners, zero extent, signed zeros,
#: NaN, infinities and values near the float range's end.
HOSTILE = [0.0, -0.0, 1.0, 2.5, 10.0, 10.0, 640.0, -3.0, math.nan, math.inf, -math.inf, 1e308]


def hostile_boxes(rng: random.Random, count: int, prefix: str) -> list[tuple[str, list[float]]]:
    boxes = []
    for i in range(count):
        if rng.random() < 0.7:  # most boxes ordinary, so that some pairs match
            x, y = rng.uniform(0, 50), rng.uniform(0, 50)
            corners = [x, y, x + rng.uniform(0, 20), y + rng.uniform(0, 20)]
            if rng.random() < 0.2:
                corners = [corners[2], corners[3], corners[0], corners[1]]
        else:
            corners = [rng.choice(HOSTILE) for _ in range(4)]
        boxes.append((f"{prefix}{i}", corners))
    return boxes


def test_batched_scores_give_each_frame_its_own_matches(monkeypatch: pytest.MonkeyPatch) -> None:
    rng = random.Random(20261208)
    for _ in range(300):
        frames = [
            (
                hostile_boxes(rng, rng.randint(1, 12), "d"),
                hostile_boxes(rng, rng.randint(1, 12), "g"),
            )
            for _ in range(rng.randint(1, 5))
        ]
        builder = LogBuilder(total_frames=10)
        for k, (det, gt) in enumerate(frames):
            ts = 100 + 50 * k
            builder.frame(ts).pose(ts, 0, 0).actor(ts, "ego", 0, 0)
            builder.boxes(ts, det, gt)
        log = builder.build()
        # no earlier log's scores (each log here is new, its frames at the same times)
        monkeypatch.setattr(oracles, "_SCORES", LRU(2 * IOU_BATCH))
        with np.errstate(all="ignore"):  # as the judging is: infinities make NaN
            same_matches_every_frame(log)


def same_matches_every_frame(log: RunLog) -> None:
    for ts in log.frames:
        det, gt = log.bboxes[ts], log.bboxes_gt[ts]
        own = _match_scores(det.corners, gt.corners)
        batched = frame_match_scores(log, ts, det, gt)
        assert batched is not None
        # the same positive scores to the bit; everything else 0 (never matched), no NaN
        assert not np.isnan(batched).any()
        assert np.array_equal(np.where(own > 0, own, 0.0), np.where(batched > 0, batched, 0.0))
        assert (own[own > 0].tobytes()) == (batched[batched > 0].tobytes())
        alone = greedy_match(det.corners, gt.corners)
        reused = greedy_match(det.corners, gt.corners, scores=batched)
        assert alone[:2] == reused[:2] and alone[2].tobytes() == reused[2].tobytes()
        a, b = judge_perception(det, gt, ts, 0.5), judge_perception(det, gt, ts, 0.5, batched)
        assert repr(a) == repr(b)  # NaN means compare equal as text


def test_a_frame_read_again_is_scored_afresh() -> None:
    builder = LogBuilder()
    for ts in (100, 150, 200):
        builder.frame(ts).pose(ts, 0, 0).actor(ts, "ego", 0, 0)
        builder.boxes(ts, [("d", (0, 0, 10, 10))], [("g", (0, 0, 10, 10))])
    log = builder.build()
    ctx = context(log)
    assert perception(ctx, 100).metrics["ious"] == [1.0]  # batches 150 and 200 with it
    # a live window's frame replaced by a later copy: its own boxes are matched
    log.bboxes[150] = make_boxes([("d", (0, 0, 10, 5))])
    assert perception(ctx, 150).metrics["ious"] == [0.5]
    # and a batch is never taken for another record at the same time (another log)
    other: Boxes = make_boxes([("g", (5, 0, 15, 10))])
    assert frame_match_scores(log, 200, log.bboxes[200], other) is not None
    hit = oracles._SCORES.lookup(200)
    assert hit is not None and hit[1] is other


def test_large_frames_are_scored_alone() -> None:
    many = [(f"d{i}", (i, 0, i + 1, 1)) for i in range(40)]
    log = LogBuilder().frame(100).boxes(100, many, many).build()
    assert frame_match_scores(log, 100, log.bboxes[100], log.bboxes_gt[100]) is None
    result = perception(context(log), 100)
    assert result.metrics["n_matched"] == 40 and result.metrics["mean_iou"] == 1.0
