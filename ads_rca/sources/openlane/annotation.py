"""OpenLane-V2 annotations as :class:`~ads_rca.sources.openlane.lanes.LaneGraph`: one
frame's lane
centerlines, traffic elements and topology, ground truth or a model's prediction.

The info file's ``annotation`` and a prediction file share one schema (docs/formats.md
"OpenLane-V2 segments"), so one parser reads both: ids (integers or text) as text, lane
points mirrored from the right-handed ego frame (y' = -y), a prediction's confidences kept.
JSON numbers only: a number written as text, a boolean or NaN is not one (but a
topology matrix's ``true``/``false`` are 1 and 0, as numpy reads them in the devkit). A
prediction's confidences are any finite number and a traffic element's ``category`` may
be absent: the devkit's format check accepts both (docs/openlane-metrics.md). A bad lane or
element is dropped with its row and column of the topology (which follow the file's list
order); a repeated id keeps the first; a matrix of the wrong shape is read as no links; each
reported with its file and field.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from ads_rca.foundation.geometry import FloatArray
from ads_rca.model import Boxes
from ads_rca.problems import DROPPED_RECORD, SKIPPED_FILE, ProblemLog, Severity
from ads_rca.sources.log.records import as_float, json_number
from ads_rca.sources.openlane.lanes import (
    ELEMENT_ATTRIBUTES,
    ELEMENT_CATEGORIES,
    UNSPECIFIED_CATEGORY,
    LaneGraph,
)

#: Ids longer than this are not kept.
MAX_TEXT = 64
#: OpenLane-V2's right-handed ego frame <-> the model's: y negated (its own inverse).
MIRROR = np.array([1.0, -1.0, 1.0])


def lane_graph(
    annotation: Mapping[str, Any],
    file: str,
    where: str,
    problems: ProblemLog,
    stamp_ms: int | None,
    predicted: bool,
) -> LaneGraph:
    """A frame's annotation (ground truth, or a prediction with confidences) as a
    :class:`LaneGraph` in the model's frame; bad entries dropped with their topology rows
    and columns, each reported."""
    report = _Reporter(file, problems, stamp_ms)
    lanes_listed = _listed(annotation, "lane_centerline", where, report)
    elements_listed = _listed(annotation, "traffic_element", where, report)
    lane_rows: list[int] = []
    lane_ids: list[str] = []
    lanes: list[FloatArray] = []
    lane_scores: list[float] = []
    for row, entry in enumerate(lanes_listed):
        field = _at(where, f"lane_centerline[{row}]")
        ident = _entry_id(entry, field, lane_ids, report)
        if ident is None:
            continue
        points = finite_array(entry.get("points"), (-1, 3))
        if points is None or len(points) < 2:
            report(f"{field}.points", "not [n >= 2][3] finite numbers", DROPPED_RECORD)
            continue
        score = _score(entry, field, predicted, report)
        if score is None:
            continue
        lane_rows.append(row)
        lane_ids.append(ident)
        lanes.append(np.stack([points[:, 0], 0.0 - points[:, 1], points[:, 2]], axis=1))
        lane_scores.append(score)
    element_rows: list[int] = []
    element_ids: list[str] = []
    boxes: list[FloatArray] = []
    categories: list[int] = []
    attributes: list[int] = []
    element_scores: list[float] = []
    for row, entry in enumerate(elements_listed):
        field = _at(where, f"traffic_element[{row}]")
        ident = _entry_id(entry, field, element_ids, report)
        if ident is None:
            continue
        corners = finite_array(entry.get("points"), (2, 2))
        attribute = _integer(entry.get("attribute"))
        if corners is None:
            report(f"{field}.points", "not [[x1, y1], [x2, y2]] finite numbers", DROPPED_RECORD)
            continue
        category = _category(entry, field, report)
        if attribute is None or not 0 <= attribute < len(ELEMENT_ATTRIBUTES):
            bound = len(ELEMENT_ATTRIBUTES) - 1
            report(
                f"{field}.attribute",
                f"{shown(entry.get('attribute'))} is not 0 to {bound}",
                DROPPED_RECORD,
            )
            continue
        score = _score(entry, field, predicted, report)
        if score is None:
            continue
        element_rows.append(row)
        element_ids.append(ident)
        boxes.append(corners.reshape(4))
        categories.append(category)
        attributes.append(attribute)
        element_scores.append(score)
    n_file, k_file = len(lanes_listed), len(elements_listed)
    lane_lane = _topology(annotation, "topology_lclc", (n_file, n_file), where, predicted, report)
    lane_element = _topology(
        annotation, "topology_lcte", (n_file, k_file), where, predicted, report
    )
    return LaneGraph(
        lane_ids=tuple(lane_ids),
        lanes=tuple(lanes),
        lane_scores=np.asarray(lane_scores, dtype=np.float64).reshape(-1),
        element_ids=tuple(element_ids),
        element_boxes=np.asarray(boxes, dtype=np.float64).reshape(-1, 4),
        element_category=np.asarray(categories, dtype=np.int64).reshape(-1),
        element_attribute=np.asarray(attributes, dtype=np.int64).reshape(-1),
        element_scores=np.asarray(element_scores, dtype=np.float64).reshape(-1),
        lane_lane=lane_lane[np.ix_(lane_rows, lane_rows)],
        lane_element=lane_element[np.ix_(lane_rows, element_rows)],
    )


def _at(where: str, key: str) -> str:
    """A problem's field: ``key`` inside ``where`` ("" for a document's top level)."""
    return f"{where}.{key}" if where else key


class _Reporter:
    """One file's problems: field, issue, action."""

    def __init__(self, file: str, problems: ProblemLog, stamp_ms: int | None) -> None:
        self.file, self.problems, self.stamp_ms = file, problems, stamp_ms

    def __call__(self, field: str, issue: str, action: str, severity: Severity = "error") -> None:
        self.problems.add(self.file, field, issue, action, severity, self.stamp_ms)


def _listed(annotation: Mapping[str, Any], key: str, where: str, report: _Reporter) -> list[Any]:
    value = annotation.get(key, [])
    if isinstance(value, list):
        return value
    report(_at(where, key), f"expected a list, found {type_name(value)}", "read as empty")
    return []


def _entry_id(entry: object, field: str, seen: list[str], report: _Reporter) -> str | None:
    """An entry's id as text (an integer or a string of at most :data:`MAX_TEXT`
    printable characters), or None (reported) for a bad or repeated one."""
    if not isinstance(entry, dict):
        report(field, f"expected an object, found {type_name(entry)}", DROPPED_RECORD)
        return None
    value = entry.get("id")
    ident: str | None = None
    if isinstance(value, int) and not isinstance(value, bool):
        ident = str(value)
    elif isinstance(value, str) and 0 < len(value) <= MAX_TEXT and value.isprintable():
        ident = value
    if ident is None:
        report(f"{field}.id", f"{shown(value)} is not an integer or short text", DROPPED_RECORD)
        return None
    if ident in seen:
        report(f"{field}.id", f"{ident} repeats an earlier id of this frame", "the first kept")
        return None
    return ident


def _category(entry: Mapping[str, Any], field: str, report: _Reporter) -> int:
    """A traffic element's category: 1 light, 2 sign, else :data:`UNSPECIFIED_CATEGORY`.
    The devkit's format check asks for none (its baseline writes none, its tutorial 0) and
    its scores never read it, so an element is never dropped for it; a value other than
    0, 1 or 2 is reported."""
    if "category" not in entry:
        return UNSPECIFIED_CATEGORY
    category = _integer(entry.get("category"))
    if category in ELEMENT_CATEGORIES:
        return category
    given = shown(entry.get("category"))
    report(f"{field}.category", f"{given} is not 0, 1 or 2", "read as unspecified", "warning")
    return UNSPECIFIED_CATEGORY


def _score(
    entry: Mapping[str, Any], field: str, predicted: bool, report: _Reporter
) -> float | None:
    """NaN for the ground truth; a prediction's confidence, any finite number (the devkit
    only ranks by it: logits score as probabilities do), or None (reported)."""
    if not predicted:
        return math.nan
    value = json_number(entry.get("confidence"))
    if not math.isfinite(value):
        given = shown(entry.get("confidence"))
        report(f"{field}.confidence", f"{given} is not a finite number", DROPPED_RECORD)
        return None
    return value


def _topology(
    annotation: Mapping[str, Any],
    key: str,
    shape: tuple[int, int],
    where: str,
    predicted: bool,
    report: _Reporter,
) -> FloatArray:
    """An adjacency matrix of the file's list order; no links (zeros) when missing or of
    the wrong shape; ``true``/``false`` as 1/0 (numpy reads them so in the devkit); text
    and NaN entries read as 0, a ground truth's non-0/1 as 1 past 0.5, each kind reported
    once. A prediction's link confidences are kept as given, any finite number: the devkit
    links past 0.5 and ranks by them."""
    field = _at(where, key)
    zeros = np.zeros(shape)
    value = annotation.get(key)
    if value is None:
        if shape[0] and shape[1]:
            report(field, "missing", "read as no links", "warning")
        return zeros
    if not isinstance(value, list):
        report(field, f"expected a matrix, found {type_name(value)}", "read as no links")
        return zeros
    if 0 in shape and all(isinstance(r, list) and not r for r in value):
        return zeros  # [] or [[], ...] for a frame without lanes or elements
    found = np.array(value, dtype=object) if _rectangular(value) else None
    if found is None or found.ndim != 2 or found.shape != shape:
        got = "not a rectangular matrix" if found is None else f"shape {found.shape}"
        report(field, f"{got}, expected {shape}", "read as no links (dropped)")
        return zeros
    flat = found.ravel()
    numeric = np.fromiter(
        (type(v) in (int, float, bool) for v in flat.tolist()), dtype=bool, count=flat.size
    )
    matrix = np.full(flat.size, np.nan)
    matrix[numeric] = [as_float(v) for v in flat[numeric].tolist()]
    matrix = matrix.reshape(shape)
    bad = ~np.isfinite(matrix)
    if bad.any():
        report(field, f"{int(bad.sum())} entries are not finite numbers", "read as 0")
        matrix[bad] = 0.0
    if not predicted:
        odd = (matrix != 0.0) & (matrix != 1.0)
        if odd.any():
            report(
                field, f"{int(odd.sum())} entries are not 0 or 1", "read as 1 past 0.5", "warning"
            )
            matrix = (matrix > 0.5).astype(np.float64)
    return matrix


def _rectangular(value: list[Any]) -> bool:
    """A list of lists of one length (so numpy makes a 2-D object array of it)."""
    if not value or not all(isinstance(row, list) for row in value):
        return False
    width = len(value[0])
    return all(len(row) == width for row in value)


# --- numbers -----------------------------------------------------------------------------


def _integer(value: object) -> int | None:
    """A JSON integer (or integral float), else None."""
    if isinstance(value, float) and value.is_integer():
        return int(value)
    return value if isinstance(value, int) and not isinstance(value, bool) else None


def finite_array(value: object, shape: tuple[int, ...]) -> FloatArray | None:
    """Nested lists of finite JSON numbers of ``shape`` (-1: any length) as floats, else
    None: text numbers, booleans, NaN and ragged rows are not numbers here."""
    if not isinstance(value, list):
        return None
    try:
        found = np.array(value)
    except ValueError:  # ragged
        return None
    if found.dtype.kind not in "iuf" or found.ndim != len(shape):
        return None
    if any(want not in (-1, got) for want, got in zip(shape, found.shape, strict=True)):
        return None
    out: FloatArray = found.astype(np.float64)
    return out if np.isfinite(out).all() else None


def type_name(value: object) -> str:
    return type(value).__name__


def shown(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def bounded_text(value: object, default: str) -> str:
    """Text from a file as kept in metadata: at most :data:`MAX_TEXT` printable characters."""
    if isinstance(value, int) and not isinstance(value, bool):
        value = str(value)
    return value[:MAX_TEXT] if isinstance(value, str) and value.isprintable() else default


def boxes_of(graph: LaneGraph, predicted: bool) -> Boxes:
    """A graph's traffic elements as 2-D boxes: the attribute as label, the category and
    attribute names and (predicted) the confidence as score."""
    extras = []
    for row in range(graph.element_count):
        category = ELEMENT_CATEGORIES[int(graph.element_category[row])]
        attribute = ELEMENT_ATTRIBUTES[int(graph.element_attribute[row])]
        extra: dict[str, Any] = {"label": attribute, "category": category, "attribute": attribute}
        if predicted:
            extra["score"] = float(graph.element_scores[row])
        extras.append(extra)
    return Boxes(graph.element_ids, graph.element_boxes.copy(), tuple(extras))


def annotation_document(graph: LaneGraph, predicted: bool) -> dict[str, Any]:
    """A graph as OpenLane-V2's annotation schema, back in its right-handed ego frame (the
    inverse of :func:`lane_graph`; confidences only for a prediction): the file of a log
    folder's ``lanes/`` and ``lanes_predicted/``."""

    def scored(entry: dict[str, Any], score: float) -> dict[str, Any]:
        return {**entry, "confidence": score} if predicted else entry

    return {
        "lane_centerline": [
            scored({"id": ident, "points": (lane * MIRROR).tolist()}, score)
            for ident, lane, score in zip(
                graph.lane_ids, graph.lanes, graph.lane_scores.tolist(), strict=True
            )
        ],
        "traffic_element": [
            scored(
                {
                    "id": ident,
                    "category": category,
                    "attribute": attribute,
                    "points": [box[:2], box[2:]],
                },
                score,
            )
            for ident, box, category, attribute, score in graph.element_rows()
        ],
        "topology_lclc": graph.lane_lane.tolist(),
        "topology_lcte": graph.lane_element.tolist(),
    }


def parse_lanes(document: Any, file: str, problems: ProblemLog, ts: int) -> LaneGraph | None:
    """A log folder's ``lanes/`` file (:func:`annotation_document` of a ground truth)."""
    return _parse(document, file, problems, ts, predicted=False)


def parse_predicted_lanes(
    document: Any, file: str, problems: ProblemLog, ts: int
) -> LaneGraph | None:
    """A log folder's ``lanes_predicted/`` file (with confidences)."""
    return _parse(document, file, problems, ts, predicted=True)


def _parse(
    document: Any, file: str, problems: ProblemLog, ts: int, predicted: bool
) -> LaneGraph | None:
    if not isinstance(document, dict):
        problems.add(
            file,
            "",
            f"expected an annotation object, found {type_name(document)}",
            SKIPPED_FILE,
            "error",
            ts,
        )
        return None
    return lane_graph(document, file, "", problems, ts, predicted)
