"""OpenLane-V2 val data shaped like the released files, and a model's results in the devkit
baseline's format, so the official devkit can judge our figures on what users really have.

The hand-made segments of ``openlane_segments.py`` are 3-lane scenes with 3-point lanes; the
released files differ in ways a scorer can get wrong: 201 points per ground-truth lane
(which the official val/test evaluation thins with ``collect(..., point_interval=20)`` to
11), 60 or more lanes and 5 to 15 traffic elements per frame, text ids, nanosecond (subset_A,
Argoverse 2) and microsecond (subset_B, nuScenes) timestamps, and a model's output as the
baseline writes it: ~200 lanes of 11 points, traffic elements without ``category``, 200 x 200
link-confidence matrices. :func:`write_released_split` writes one case of that, reproducibly
(``numpy.random.default_rng(seed)``):

- ``<root>/data_dict_synthetic.json``: ``{"val": {segment: ["<timestamp>.json", ...]}}``,
  the released index's shape, which the devkit's ``collect`` takes as ``data_dict``;
- ``<root>/val/<segment>/info/<timestamp>.json``: ``version``, ``segment_id``,
  ``meta_data``, ``timestamp``, ``sensor`` (one front camera with the ``intrinsic`` and
  ``extrinsic`` ``collect`` converts), ``pose`` {rotation, translation} and ``annotation``;
- ``<root>/predictions/<segment>/<timestamp>.json``: the frame's result under
  ``predictions``, as the devkit's per-frame result (what ``--predictions`` reads);
- ``<root>/results.json``: the devkit's whole results dict in JSON (tokens as
  ``split/segment/timestamp``, arrays as lists), which :func:`devkit_results` turns into the
  dict ``evaluate`` takes. A pickle is not written: numpy 2 pickles do not load under the
  devkit's numpy < 1.24, so the devkit side makes its own from this file.

This module needs only numpy and the standard library, so the devkit's own environment can
import it too (:func:`scored_pairs` and :func:`cli_scores`, our side, import ads_rca when
called). Every coordinate is a multiple of 2^-8 m (boxes 2^-4 px), exact in float32:
the devkit reads points as float32 and we read float64, and both must see the same numbers.

Cases (:data:`CASES`): every case has the same ground truth (so the thinning of its
201-point lanes is in all of them) and, but ``identical``, the same noisy detections; each
then varies one thing a model's file may hold:

- ``identical``: the ground truth as the devkit scores it (lanes thinned ``[::20]``, boxes,
  attributes and categories, the truth's links at 1.0), every confidence 1: OLS 1.0;
- ``baseline_noisy``: ~200 lanes of 11 points with offsets, jitter, misses, duplicates,
  a few reversed, false positives; boxes jittered, some of the wrong attribute, missed or
  false; confidences in [0, 1]; link confidences in [0, 1];
- ``logits``: the same model giving raw scores in [-3, 5] (``-3 + 8 p``) everywhere;
- ``bool_topology``: the same lanes with links as JSON booleans (true only on a link of
  the truth the model kept: booleans tie, and ties between a true and a false link would
  leave the figure to the devkit's unstable quicksort);
- ``elements_no_category``: the same model with traffic elements as the baseline writes
  them, ``{id, attribute, points, confidence}`` without ``category``.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:
    from ads_rca.sources.openlane.lanes import LaneGraph

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

SPLIT = "val"
#: The released index's shape; ``collect`` takes its content as ``data_dict``.
DATA_DICT = "data_dict_synthetic.json"
RESULTS = "results.json"
PREDICTIONS = "predictions"
#: The devkit's thinning of ground-truth lanes for the official val/test evaluation.
POINT_INTERVAL = 20
SEED = 39


@dataclass(frozen=True)
class Segment:
    """A segment: its name, timestamp unit, first stamp and step (unit per frame)."""

    name: str
    unit: str
    first: int
    step: int
    source: str


#: One Argoverse 2-like segment (ns) and one nuScenes-like (µs), both 2 Hz.
SEGMENTS = (
    Segment("10000", "ns", 315_969_904_359_876_000, 500_000_000, "av2"),
    Segment("11000", "us", 1_533_201_470_412_460, 500_000, "nuscenes"),
)


@dataclass(frozen=True)
class Shape:
    """How big the frames are: everything the figures depend on besides the seed."""

    frames_per_segment: int = 3
    lane_points: int = 201
    gt_lanes: tuple[int, int] = (60, 72)
    elements: tuple[int, int] = (5, 15)
    predicted_lanes: int = 200
    predicted_points: int = 11
    image_size: tuple[int, int] = (2048, 1550)


@dataclass(frozen=True)
class Case:
    """One case: the model's flavour (:data:`CASES`)."""

    name: str
    noisy: bool = True
    #: ``unit``: confidences in [0, 1]; ``logit``: raw scores ``-3 + 8 p``.
    confidence: str = "unit"
    #: ``float`` link confidences or ``bool`` links.
    topology: str = "float"
    element_category: bool = True


DEFAULT_SHAPE = Shape()
CASES = {
    case.name: case
    for case in (
        Case("identical", noisy=False),
        Case("baseline_noisy"),
        Case("logits", confidence="logit"),
        Case("bool_topology", topology="bool"),
        Case("elements_no_category", element_category=False),
    )
}
#: Attributes 0..12 (devkit ``TRAFFIC_ELEMENT_ATTRIBUTE``); lights are red/green/yellow.
ATTRIBUTES = 13
LIGHT_ATTRIBUTES = (1, 2, 3)
LANE_WIDTH_M = 3.5
#: Coordinates are multiples of these (exact in float32).
METRE_QUANTUM = 2.0**-8
PIXEL_QUANTUM = 2.0**-4


@dataclass(frozen=True)
class Graph:
    """One frame's lanes, elements and links, ground truth or predicted (confidences)."""

    lane_ids: list[str]
    lanes: list[FloatArray]  # (P, 3) each, right-handed ego frame
    lane_confidence: FloatArray
    element_ids: list[str]
    boxes: FloatArray  # (k, 2, 2) [[x1, y1], [x2, y2]]
    category: IntArray
    attribute: IntArray
    element_confidence: FloatArray
    lclc: FloatArray  # (n, n)
    lcte: FloatArray  # (n, k)


@dataclass(frozen=True)
class Frame:
    segment: Segment
    timestamp: int
    index: int
    truth: Graph
    prediction: Graph


def parameters(shape: Shape = DEFAULT_SHAPE, seed: int = SEED) -> dict[str, Any]:
    """The generator's parameters, as a golden file pins them."""
    return {
        "module": "test/writers/openlane_released.py",
        "seed": seed,
        "split": SPLIT,
        "segments": [asdict(s) for s in SEGMENTS],
        **{k: list(v) if isinstance(v, tuple) else v for k, v in asdict(shape).items()},
        "cases": {name: asdict(case) for name, case in CASES.items()},
    }


# --- the scene ---------------------------------------------------------------------------


def _quantised(values: FloatArray, quantum: float) -> FloatArray:
    return np.round(np.asarray(values, dtype=np.float64) / quantum) * quantum


def _arc(rng: np.random.Generator, start: FloatArray, heading: float, count: int) -> FloatArray:
    """A lane-like curve of ``count`` points from ``start`` (x, y, z) along ``heading``:
    10-30 m long, radius 33 m or more, a gentle grade."""
    length = rng.uniform(10.0, 30.0)
    curvature = rng.uniform(-0.03, 0.03)
    grade = rng.uniform(-0.03, 0.03)
    s = np.linspace(0.0, length, count)
    theta = heading + curvature * s
    if abs(curvature) < 1e-9:
        x, y = start[0] + s * math.cos(heading), start[1] + s * math.sin(heading)
    else:
        x = start[0] + (np.sin(theta) - math.sin(heading)) / curvature
        y = start[1] - (np.cos(theta) - math.cos(heading)) / curvature
    return np.stack([x, y, start[2] + grade * s], axis=1)


def _heading_at_end(line: FloatArray) -> float:
    dx, dy = line[-1, :2] - line[-2, :2]
    return math.atan2(dy, dx)


def _offset(line: FloatArray, metres: float) -> FloatArray:
    """``line`` moved ``metres`` to its left (a neighbouring lane of the same road)."""
    tangent = np.gradient(line[:, :2], axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    moved = line.copy()
    moved[:, 0] -= metres * tangent[:, 1]
    moved[:, 1] += metres * tangent[:, 0]
    return moved


def _road(rng: np.random.Generator, points: int) -> tuple[list[FloatArray], list[tuple[int, int]]]:
    """A road of 1-3 parallel lanes and 2-4 consecutive pieces, some pieces forking into a
    turn: its lanes and links (successor pairs, indices into its lanes)."""
    width = int(rng.integers(1, 4))
    pieces = int(rng.integers(2, 5))
    start = np.array([rng.uniform(-45, 45), rng.uniform(-22, 22), rng.uniform(-0.5, 0.5)])
    heading = rng.uniform(-math.pi, math.pi)
    lanes: list[FloatArray] = []
    links: list[tuple[int, int]] = []
    previous: list[int] = []
    for _ in range(pieces):
        axis = _arc(rng, start, heading, points)
        current = []
        for k in range(width):
            current.append(len(lanes))
            lanes.append(_offset(axis, k * LANE_WIDTH_M))
        links.extend(zip(previous, current, strict=True) if previous else [])
        if rng.random() < 0.3:  # the rightmost lane of this piece forks into a turn
            turn = _arc(rng, lanes[current[0]][-1], _heading_at_end(lanes[current[0]]), points)
            links.append((current[0], len(lanes)))
            lanes.append(turn)
        previous = current
        start, heading = axis[-1], _heading_at_end(axis)
    return lanes, links


def _truth(rng: np.random.Generator, shape: Shape, attributes: Sequence[int]) -> Graph:
    """A frame's ground truth: roads until the lane count is reached, in shuffled order."""
    target = int(rng.integers(shape.gt_lanes[0], shape.gt_lanes[1] + 1))
    lanes: list[FloatArray] = []
    links: list[tuple[int, int]] = []
    while len(lanes) < target:
        road, road_links = _road(rng, shape.lane_points)
        base = len(lanes)
        lanes.extend(road)
        links.extend((a + base, b + base) for a, b in road_links)
    lanes = lanes[:target]
    order = rng.permutation(target)  # files list lanes in no road order
    position = np.empty(target, dtype=np.int64)
    position[order] = np.arange(target)
    lclc = np.zeros((target, target))
    for a, b in links:
        if a < target and b < target:
            lclc[position[a], position[b]] = 1.0
    lanes = [_quantised(lanes[i], METRE_QUANTUM) for i in order.tolist()]
    count = len(attributes)
    width, height = shape.image_size
    corner = np.stack([rng.uniform(0, width - 200, count), rng.uniform(0, height - 200, count)])
    size = np.stack([rng.uniform(20, 150, count), rng.uniform(20, 150, count)])
    boxes = _quantised(np.stack([corner.T, (corner + size).T], axis=1), PIXEL_QUANTUM)
    attribute = np.asarray(attributes, dtype=np.int64)
    category = np.where(np.isin(attribute, LIGHT_ATTRIBUTES), 1, 2)
    category[attribute == 0] = rng.integers(1, 3, int((attribute == 0).sum()))
    lcte = np.zeros((target, count))
    for element in range(count):
        if rng.random() < 0.85:  # most elements govern 1-4 lanes
            governed = rng.choice(target, size=int(rng.integers(1, 5)), replace=False)
            lcte[governed, element] = 1.0
    return Graph(
        lane_ids=[str(100 + i) for i in range(target)],
        lanes=lanes,
        lane_confidence=np.full(target, np.nan),
        element_ids=[str(900 + j) for j in range(count)],
        boxes=boxes,
        category=category.astype(np.int64),
        attribute=attribute,
        element_confidence=np.full(count, np.nan),
        lclc=lclc,
        lcte=lcte,
    )


def _segment_attributes(rng: np.random.Generator, shape: Shape) -> list[list[int]]:
    """Per frame, its elements' attributes: every attribute in every segment (so a
    segment's DET_t averages all 13 classes, under any empty-class rule)."""
    counts = [
        int(rng.integers(*shape.elements, endpoint=True)) for _ in range(shape.frames_per_segment)
    ]
    while sum(counts) < ATTRIBUTES:
        counts[int(np.argmin(counts))] += 1
    cycle = (int(rng.integers(ATTRIBUTES)) + np.arange(sum(counts))) % ATTRIBUTES
    cycle = rng.permutation(cycle)
    ends = np.cumsum(counts)
    return [cycle[end - n : end].tolist() for n, end in zip(counts, ends, strict=True)]


# --- the model ---------------------------------------------------------------------------


@dataclass(frozen=True)
class _Detections:
    """The noisy model's output before its confidences are written: per predicted lane the
    true lane it came from (-1: a false positive), per predicted element likewise."""

    lanes: list[FloatArray]
    lane_source: IntArray
    lane_p: FloatArray
    boxes: FloatArray
    attribute: IntArray
    category: IntArray
    element_source: IntArray
    element_p: FloatArray


def _thinned(lane: FloatArray, count: int) -> FloatArray:
    """``count`` points of ``lane`` evenly by index (201 -> 11 is the devkit's ``[::20]``)."""
    return lane[np.linspace(0, len(lane) - 1, count).round().astype(np.int64)]


def _noisy_lanes(
    rng: np.random.Generator, truth: Graph, shape: Shape
) -> tuple[list[FloatArray], list[int], list[float]]:
    lanes: list[FloatArray] = []
    source: list[int] = []
    p: list[float] = []
    for g, lane in enumerate(truth.lanes):
        copies = 0 if rng.random() < 0.12 else (2 if rng.random() < 0.1 else 1)
        for copy in range(copies):
            error = rng.uniform(0.0, 1.6) * (1.0 + copy)
            shift = rng.normal(0.0, 1.0, 3) * np.array([error, error, 0.1]) / math.sqrt(2)
            line = _thinned(lane, shape.predicted_points) + shift
            line += rng.normal(0.0, 0.15, line.shape)
            if rng.random() < 0.03:
                line = line[::-1]
            lanes.append(line)
            source.append(g)
            p.append(float(np.clip(0.95 - 0.3 * error + rng.normal(0, 0.08), 0.02, 0.99)))
    while len(lanes) < shape.predicted_lanes:
        start = np.array([rng.uniform(-50, 50), rng.uniform(-25, 25), 0.0])
        lanes.append(_arc(rng, start, rng.uniform(-math.pi, math.pi), shape.predicted_points))
        source.append(-1)
        p.append(float(rng.uniform(0.0, 0.6) ** 1.5))
    return lanes, source, p


def _noisy_elements(
    rng: np.random.Generator, truth: Graph, shape: Shape
) -> tuple[FloatArray, list[int], list[int], list[int], list[float]]:
    boxes: list[FloatArray] = []
    attribute: list[int] = []
    category: list[int] = []
    source: list[int] = []
    p: list[float] = []
    for j, box in enumerate(truth.boxes):
        if rng.random() < 0.1:
            continue
        size = box[1] - box[0]
        moved = box + rng.normal(0.0, 0.12, (2, 2)) * size
        lo, hi = np.minimum(moved[0], moved[1] - 2.0), moved[1]
        boxes.append(np.stack([lo, hi]))
        wrong = rng.random() < 0.15
        attribute.append(int(rng.integers(ATTRIBUTES)) if wrong else int(truth.attribute[j]))
        category.append(int(truth.category[j]))
        source.append(j)
        p.append(float(np.clip(rng.normal(0.75, 0.15), 0.02, 0.99)))
    width, height = shape.image_size
    for _ in range(int(rng.integers(0, 4))):
        corner = np.array([rng.uniform(0, width - 200), rng.uniform(0, height - 200)])
        boxes.append(np.stack([corner, corner + rng.uniform(20, 150, 2)]))
        attribute.append(int(rng.integers(ATTRIBUTES)))
        category.append(int(rng.integers(1, 3)))
        source.append(-1)
        p.append(float(rng.uniform(0.0, 0.5)))
    return np.asarray(boxes).reshape(-1, 2, 2), attribute, category, source, p


def _detections(rng: np.random.Generator, truth: Graph, shape: Shape) -> _Detections:
    lanes, lane_source, lane_p = _noisy_lanes(rng, truth, shape)
    order = rng.permutation(len(lanes))  # a model's queries come in no particular order
    boxes, attribute, category, element_source, element_p = _noisy_elements(rng, truth, shape)
    return _Detections(
        lanes=[_quantised(lanes[i], METRE_QUANTUM) for i in order.tolist()],
        lane_source=np.asarray(lane_source, dtype=np.int64)[order],
        lane_p=np.asarray(lane_p)[order],
        boxes=_quantised(boxes, PIXEL_QUANTUM),
        attribute=np.asarray(attribute, dtype=np.int64),
        category=np.asarray(category, dtype=np.int64),
        element_source=np.asarray(element_source, dtype=np.int64),
        element_p=np.asarray(element_p),
    )


def _link_confidence(
    rng: np.random.Generator, truth: FloatArray, rows: IntArray, cols: IntArray
) -> tuple[FloatArray, BoolArray]:
    """Link confidences between predicted vertices whose true sources are ``rows`` and
    ``cols`` (-1: none): true links mostly above 0.5, others mostly below; and which entries
    are true links of the truth (for the boolean flavour)."""
    known = (rows[:, None] >= 0) & (cols[None, :] >= 0)
    true = np.zeros(known.shape, dtype=bool)
    true[known] = truth[np.ix_(np.maximum(rows, 0), np.maximum(cols, 0))][known] > 0
    kept = rng.random(true.shape) < 0.85
    high = rng.uniform(0.5, 1.0, true.shape)
    low = rng.uniform(0.0, 0.5, true.shape)
    spurious = (rng.random(true.shape) < 0.01) & known
    confidence = np.where(true & kept, high, low)
    confidence = np.where(~true & spurious, rng.uniform(0.5, 0.9, true.shape), confidence)
    return np.asarray(np.round(confidence, 6), dtype=np.float64), true & kept


def _prediction(rng: np.random.Generator, truth: Graph, shape: Shape, case: Case) -> Graph:
    """The case's model output for a frame (see the module docstring)."""
    if not case.noisy:
        n, k = len(truth.lanes), len(truth.element_ids)
        return Graph(
            lane_ids=[str(i) for i in range(n)],
            lanes=[lane[::POINT_INTERVAL] for lane in truth.lanes],
            lane_confidence=np.ones(n),
            element_ids=[str(shape.predicted_lanes + j) for j in range(k)],
            boxes=truth.boxes,
            category=truth.category,
            attribute=truth.attribute,
            element_confidence=np.ones(k),
            lclc=truth.lclc.copy(),
            lcte=truth.lcte.copy(),
        )
    found = _detections(rng, truth, shape)
    lclc, lclc_kept = _link_confidence(rng, truth.lclc, found.lane_source, found.lane_source)
    lcte, lcte_kept = _link_confidence(rng, truth.lcte, found.lane_source, found.element_source)
    lane_p, element_p = found.lane_p, found.element_p
    if case.confidence == "logit":
        lane_p, element_p, lclc, lcte = (-3.0 + 8.0 * v for v in (lane_p, element_p, lclc, lcte))
        lclc, lcte = np.round(lclc, 6), np.round(lcte, 6)
    if case.topology == "bool":
        lclc, lcte = lclc_kept.astype(np.float64), lcte_kept.astype(np.float64)
    return Graph(
        lane_ids=[str(i) for i in range(len(found.lanes))],
        lanes=found.lanes,
        lane_confidence=lane_p,
        element_ids=[str(shape.predicted_lanes + j) for j in range(len(found.attribute))],
        boxes=found.boxes,
        category=found.category,
        attribute=found.attribute,
        element_confidence=element_p,
        lclc=lclc,
        lcte=lcte,
    )


def frames(case: Case, shape: Shape = DEFAULT_SHAPE, seed: int = SEED) -> list[Frame]:
    """Every frame of the split for ``case``. The ground truth and the noisy model's
    detections depend on the seed only, so cases differ only in what they vary."""
    found: list[Frame] = []
    for s, segment in enumerate(SEGMENTS):
        rng = np.random.default_rng([seed, s])
        attributes = _segment_attributes(rng, shape)
        for index in range(shape.frames_per_segment):
            truth = _truth(rng, shape, attributes[index])
            model = np.random.default_rng([seed, s, index])
            found.append(
                Frame(
                    segment=segment,
                    timestamp=segment.first + index * segment.step,
                    index=index,
                    truth=truth,
                    prediction=_prediction(model, truth, shape, case),
                )
            )
    return found


# --- the documents -----------------------------------------------------------------------


def _rotation(yaw: float) -> list[list[float]]:
    c, s = math.cos(yaw), math.sin(yaw)
    return [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]


def info_document(frame: Frame) -> dict[str, Any]:
    """The frame's info file, with the fields the devkit's ``collect`` reads."""
    segment, stamp, truth = frame.segment, frame.timestamp, frame.truth
    yaw = 0.3 + 0.01 * frame.index
    distance = 5.0 * frame.index
    camera = "ring_front_center" if segment.source == "av2" else "CAM_FRONT"
    return {
        "version": "v2.0",
        "segment_id": segment.name,
        "meta_data": {"source": segment.source, "source_id": f"{segment.source}-{segment.name}"},
        "timestamp": stamp,
        "sensor": {
            camera: {
                "image_path": f"{SPLIT}/{segment.name}/image/{camera}/{stamp}.jpg",
                "extrinsic": {
                    "rotation": [[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]],
                    "translation": [1.6, 0.0, 1.4],
                },
                "intrinsic": {
                    "K": [[1777.0, 0.0, 1024.0], [0.0, 1777.0, 775.0], [0.0, 0.0, 1.0]],
                    "distortion": [],
                },
            }
        },
        "pose": {
            "rotation": _rotation(yaw),
            "translation": [
                1200.0 + distance * math.cos(yaw),
                -300.0 + distance * math.sin(yaw),
                12.0,
            ],
        },
        "annotation": _annotation(truth, predicted=False, category=True),
    }


def _annotation(graph: Graph, predicted: bool, category: bool) -> dict[str, Any]:
    """The annotation schema (ground truth) or a result (with confidences) as JSON values."""

    def scored(entry: dict[str, Any], confidence: float) -> dict[str, Any]:
        return {**entry, "confidence": float(confidence)} if predicted else entry

    lanes = [
        scored({"id": ident, "points": lane.tolist()}, confidence)
        for ident, lane, confidence in zip(
            graph.lane_ids, graph.lanes, graph.lane_confidence, strict=True
        )
    ]
    if not predicted:
        for lane in lanes:
            lane["is_intersection_or_connector"] = False
    elements = []
    for j, ident in enumerate(graph.element_ids):
        entry: dict[str, Any] = {"id": ident}
        if category:
            entry["category"] = int(graph.category[j])
        entry["attribute"] = int(graph.attribute[j])
        entry["points"] = graph.boxes[j].tolist()
        elements.append(scored(entry, graph.element_confidence[j]))
    return {
        "lane_centerline": lanes,
        "traffic_element": elements,
        "topology_lclc": _matrix(graph.lclc, predicted),
        "topology_lcte": _matrix(graph.lcte, predicted),
    }


def _matrix(values: FloatArray, predicted: bool) -> list[list[Any]]:
    """Ground truth as 0/1 integers; predictions as given (floats or booleans)."""
    return (values.tolist() if predicted else values.astype(np.int64).tolist()) or []


def prediction_document(frame: Frame, case: Case) -> dict[str, Any]:
    """The frame's result file: the devkit's per-frame result, ``{"predictions": ...}``."""
    result = _annotation(frame.prediction, predicted=True, category=case.element_category)
    if case.topology == "bool":
        result["topology_lclc"] = frame.prediction.lclc.astype(bool).tolist()
        result["topology_lcte"] = frame.prediction.lcte.astype(bool).tolist()
    return {PREDICTIONS: result}


def token(frame: Frame) -> str:
    """The devkit's frame key (split, segment, timestamp) as one text."""
    return f"{SPLIT}/{frame.segment.name}/{frame.timestamp}"


def data_dict(found: Sequence[Frame]) -> dict[str, dict[str, list[str]]]:
    """The released index: split -> segment -> info file names."""
    index: dict[str, list[str]] = {}
    for frame in found:
        index.setdefault(frame.segment.name, []).append(f"{frame.timestamp}.json")
    return {SPLIT: index}


def write_released_split(
    root: Path, case: Case, shape: Shape = DEFAULT_SHAPE, seed: int = SEED
) -> list[Frame]:
    """``case``'s split under ``root`` (the module docstring's files); its frames."""
    found = frames(case, shape, seed)
    root.mkdir(parents=True, exist_ok=True)
    (root / DATA_DICT).write_text(json.dumps(data_dict(found)), encoding="utf-8")
    results: dict[str, Any] = {}
    for frame in found:
        info = root / SPLIT / frame.segment.name / "info"
        predicted = root / PREDICTIONS / frame.segment.name
        info.mkdir(parents=True, exist_ok=True)
        predicted.mkdir(parents=True, exist_ok=True)
        name = f"{frame.timestamp}.json"
        (info / name).write_text(json.dumps(info_document(frame)), encoding="utf-8")
        document = prediction_document(frame, case)
        (predicted / name).write_text(json.dumps(document), encoding="utf-8")
        results[token(frame)] = document
    header = {
        "method": f"synthetic {case.name}",
        "e-mail": "nobody@example.com",
        "institution / company": "ads_rca tests",
        "country / region": "DE",
        "authors": ["ads_rca"],
    }
    (root / RESULTS).write_text(json.dumps({**header, "results": results}), encoding="utf-8")
    return found


def segment_folder(root: Path, segment: Segment) -> Path:
    return root / SPLIT / segment.name


def prediction_folder(root: Path, segment: Segment) -> Path:
    return root / PREDICTIONS / segment.name


def devkit_results(
    document: Mapping[str, Any], segments: Sequence[str] | None = None
) -> dict[str, Any]:
    """``results.json`` as the dict the devkit's ``evaluate`` takes: tuple tokens, points as
    float32 arrays (as the baseline writes them), link matrices as arrays; only the frames
    of ``segments`` if given."""
    results: dict[tuple[str, str, str], Any] = {}
    for key, entry in document["results"].items():
        split, segment, stamp = key.split("/")
        if segments is not None and segment not in segments:
            continue
        predicted = entry[PREDICTIONS]
        results[(split, segment, stamp)] = {
            PREDICTIONS: {
                "lane_centerline": [
                    {**lane, "points": np.array(lane["points"], dtype=np.float32)}
                    for lane in predicted["lane_centerline"]
                ],
                "traffic_element": [
                    {**element, "points": np.array(element["points"], dtype=np.float32)}
                    for element in predicted["traffic_element"]
                ],
                **{key: np.array(predicted[key]) for key in ("topology_lclc", "topology_lcte")},
            }
        }
    return {**{k: v for k, v in document.items() if k != "results"}, "results": results}


# --- our side (ads_rca imported on call: the devkit's environment never calls these) ------

#: The figures compared with the devkit's, by ``OpenLaneScores.to_dict`` key.
FIGURES = ("det_l", "det_t", "top_ll", "top_lt", "ols")


def scored_pairs(root: Path) -> list[tuple[LaneGraph, LaneGraph]]:
    """Every scored (ground truth, prediction) frame of the split as ``diagnose`` reads it:
    each segment through the OpenLane-V2 reader with its ``predictions`` folder, the frames
    chosen as the run's scorer chooses them."""
    from ads_rca.sources.formats import SourceOptions
    from ads_rca.sources.openlane.reader import read_openlane_segment
    from ads_rca.sources.openlane.run_scores import scored_pair

    pairs: list[tuple[LaneGraph, LaneGraph]] = []
    for segment in SEGMENTS:
        source = SourceOptions(predictions=str(prediction_folder(root, segment)))
        log = read_openlane_segment(segment_folder(root, segment), source=source)
        for stamp in log.frames:
            pair = scored_pair(log, stamp)
            if pair is not None:
                pairs.append((pair[0], pair[1]))
    return pairs


def cli_scores(root: Path, segment: Segment, out: Path) -> dict[str, Any]:
    """The verdict JSON's ``openlane_scores`` of ``ads_rca.cli diagnose`` on one segment with
    its predictions ({} if it has none); the JSON is written to ``out``."""
    command = [
        sys.executable,
        "-m",
        "ads_rca.cli",
        "diagnose",
        str(segment_folder(root, segment)),
        "--format",
        "openlane",
        "--predictions",
        str(prediction_folder(root, segment)),
        "--json",
        str(out),
    ]
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(command)}: exit {done.returncode}: {done.stderr[-2000:]}")
    scores = json.loads(out.read_text(encoding="utf-8")).get("openlane_scores") or {}
    return dict(scores)
