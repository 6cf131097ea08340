"""Map perception of one frame: lane centerlines, traffic elements and their topology.

OpenLane-V2 frames carry what a map-perception model sees instead of actors:
3-D lane centerlines in the ego frame, 2-D traffic elements (lights and signs) in the front
camera's image, and two adjacency matrices (lane -> lane, lane -> traffic element). The same
structure holds the ground truth (``scores`` NaN, adjacency 0 or 1) and a model's prediction
(``scores`` its confidences, adjacency its link confidences in [0, 1]), so one scorer
compares them (``ads_rca.sources.openlane.scores``) and one converter publishes either.

Pure data, no I/O. Lane points are in the model's ego frame (x forward, y RIGHT as CARLA's
left-handed frame, z up): a reader of a right-handed source mirrors y. Ids are text (the
dataset's files hold ints or strings).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

#: OpenLane-V2's traffic-element categories; 0: not given (the devkit baseline writes
#: none, its tutorial 0). The scores never use the category (docs/openlane-metrics.md).
UNSPECIFIED_CATEGORY = 0
ELEMENT_CATEGORIES = {UNSPECIFIED_CATEGORY: "unspecified", 1: "traffic_light", 2: "road_sign"}
#: OpenLane-V2's traffic-element attributes (the index is the file's ``attribute``).
ELEMENT_ATTRIBUTES = (
    "unknown",
    "red",
    "green",
    "yellow",
    "go_straight",
    "turn_left",
    "turn_right",
    "no_left_turn",
    "no_right_turn",
    "u_turn",
    "no_u_turn",
    "slight_left",
    "slight_right",
)


@dataclass(frozen=True, eq=False)
class LaneGraph:
    """One frame's lane centerlines and traffic elements, ground truth or predicted.

    ``lanes[i]`` is centerline i's (P_i, 3) points in order of travel; ``lane_scores`` its
    confidence (NaN for ground truth). ``element_boxes`` rows are (x1, y1, x2, y2) image
    pixels; ``element_category`` 1 light / 2 sign / 0 not given, ``element_attribute`` an index of
    :data:`ELEMENT_ATTRIBUTES`. ``lane_lane`` is (n, n) with [i, j] the link i -> j;
    ``lane_element`` (n, k) with [i, j] lane i governed by element j. Rows and columns follow
    the list order.
    """

    lane_ids: tuple[str, ...]
    lanes: tuple[FloatArray, ...]
    lane_scores: FloatArray  # (n,)
    element_ids: tuple[str, ...]
    element_boxes: FloatArray  # (k, 4)
    element_category: IntArray  # (k,)
    element_attribute: IntArray  # (k,)
    element_scores: FloatArray  # (k,)
    lane_lane: FloatArray  # (n, n)
    lane_element: FloatArray  # (n, k)

    def __post_init__(self) -> None:
        n, k = len(self.lane_ids), len(self.element_ids)
        shapes = {
            "lanes": (len(self.lanes), n),
            "lane_scores": (self.lane_scores.shape, (n,)),
            "element_boxes": (self.element_boxes.shape, (k, 4)),
            "element_category": (self.element_category.shape, (k,)),
            "element_attribute": (self.element_attribute.shape, (k,)),
            "element_scores": (self.element_scores.shape, (k,)),
            "lane_lane": (self.lane_lane.shape, (n, n)),
            "lane_element": (self.lane_element.shape, (n, k)),
        }
        for name, (found, expected) in shapes.items():
            if found != expected:
                raise ValueError(f"LaneGraph.{name}: shape {found}, expected {expected}")

    @property
    def lane_count(self) -> int:
        return len(self.lane_ids)

    @property
    def element_count(self) -> int:
        return len(self.element_ids)

    def element_rows(self) -> list[tuple[str, list[float], int, int, float]]:
        """Each traffic element as plain values: (id, box, category, attribute, score), the
        one walk the writers of a graph (log folders, markers) share."""
        return list(
            zip(
                self.element_ids,
                self.element_boxes.tolist(),
                self.element_category.tolist(),
                self.element_attribute.tolist(),
                self.element_scores.tolist(),
                strict=True,
            )
        )

    @classmethod
    def empty(cls) -> LaneGraph:
        """A frame that sees nothing."""
        return cls(
            lane_ids=(),
            lanes=(),
            lane_scores=np.zeros(0),
            element_ids=(),
            element_boxes=np.zeros((0, 4)),
            element_category=np.zeros(0, dtype=np.int64),
            element_attribute=np.zeros(0, dtype=np.int64),
            element_scores=np.zeros(0),
            lane_lane=np.zeros((0, 0)),
            lane_element=np.zeros((0, 0)),
        )
