"""A frame's IoU matrix of detections x ground-truth boxes, computed a batch of frames at once.

Why: a frame's hundred box pairs cost a dozen numpy calls; computed with the frames that
follow it (``diagnose`` and a live monitor judge them next) they cost a fraction of that.
Both modes' perception rules take their matrices from here, each with a cache of its own.
"""

from __future__ import annotations

from ads_rca.foundation.geometry import FloatArray, axis_aligned_ious
from ads_rca.model import Boxes, RunLog
from ads_rca.oracles.cache import LRU

#: Frames whose IoU matrices are computed in one batch: the one judged and those after it.
IOU_BATCH = 64
#: Frames with more detection x gt pairs than this are not batched (their rule scores them).
BATCH_PAIRS = 1024

#: A frame's detections and gt boxes, and their IoU matrix (NaN coordinates score 0).
FrameIoU = tuple[Boxes, Boxes, FloatArray]


def batched_iou(
    log: RunLog, cache: LRU[int, FrameIoU], ts: int, det: Boxes, gt: Boxes
) -> FloatArray | None:
    """The IoU matrix of ``det`` x ``gt`` at ts (NaN coordinates score 0), or None where the
    frame is too large (or empty) to batch.

    A cached matrix is used only for the very box objects it was computed from (the cache
    keeps them alive, so their identity is no other record's): a live window's late or
    replaced frame, or another log's frame at the same time, is scored afresh. A batch
    stops at the first frame missing, too large or already in ``cache`` for its very
    records (so frames judged backwards batch nothing); a frame cached for other records
    is scored again in the batch.
    """
    if not 0 < len(det) * len(gt) <= BATCH_PAIRS:
        return None
    found = _cached(cache, ts, det, gt)
    if found is not None:
        return found
    batch = [(ts, det, gt)]
    detections, truths, frame_ms = log.bboxes, log.bboxes_gt, log.frame_ms
    for u in range(ts + frame_ms, ts + IOU_BATCH * frame_ms, frame_ms) if frame_ms > 0 else ():
        d, g = detections.get(u), truths.get(u)
        if d is None or g is None or not 0 < len(d) * len(g) <= BATCH_PAIRS:
            break
        if _cached(cache, u, d, g) is not None:
            break
        batch.append((u, d, g))
    ious = axis_aligned_ious(
        [d.corners for _, d, _ in batch], [g.corners for _, _, g in batch], nan_score=0.0
    )
    for (u, d, g), iou in zip(batch, ious, strict=True):
        cache.put(u, (d, g, iou))
    return ious[0]


def _cached(cache: LRU[int, FrameIoU], ts: int, det: Boxes, gt: Boxes) -> FloatArray | None:
    """The matrix cached at ts if it was computed from these very records."""
    hit = cache.lookup(ts)
    return hit[2] if hit is not None and hit[0] is det and hit[1] is gt else None
