"""A table of independent ego snapshots (atmaCup #18): per row, the vehicle state, the
realised future ego path and, when a model's submission is given, its predicted path.

Such a table is no time series: each row is one moment of some scene, the next row may be
ten seconds later or another scene. Its frames (one per row) hold what a frame can hold
(the ego at the origin, its 2-D detections); what belongs to the row as a whole lives here,
in one columnar record for the run, so a scorer works on every row at once:

- ``realised`` and ``predicted``: (rows, 6, 3) ego positions at t + 0.5 … 3.0 s
  (:data:`HORIZONS_S`) in the model's frame at t (x forward, y RIGHT, z up: the table's
  right-handed y mirrored), NaN where the table or the submission gives none;
- ``vehicle``: the table's CAN fields per row, by their column names, in the table's own
  units and signs (``steeringAngleDeg`` counter-clockwise positive, not mirrored); booleans
  as 1.0 / 0.0; NaN where a value is unusable; ``gear`` the gear lever's text.

The ``model.Plan`` slot is not used for either path: it has no z (the competition scores
z) and its keys count frames ahead, which in a table of snapshots would point into other
rows (a rule following the plan across frames would compare unrelated moments).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

#: The future instants of a row's path, seconds after the row's moment.
HORIZONS_S = (0.5, 1.0, 1.5, 2.0, 2.5, 3.0)
#: The largest coordinate of a path (metres) that can be scored: a difference of two, its
#: square and the sums over every row stay finite. A larger one (``1e308``) overflowed into
#: numpy warnings and an MAE of inf shown as "None" (issue 43): it is read as no value and
#: reported, its row not scored.
MAX_PATH_VALUE = 1e150
#: The table's target columns in the competition's order: x_0, y_0, z_0, …, z_5.
TARGET_COLUMNS = tuple(f"{axis}_{n}" for n in range(len(HORIZONS_S)) for axis in "xyz")
#: The table's CAN fields kept per row (numbers; the booleans as 1.0 / 0.0).
VEHICLE_COLUMNS = (
    "vEgo",
    "aEgo",
    "steeringAngleDeg",
    "steeringTorque",
    "brake",
    "brakePressed",
    "gas",
    "gasPressed",
    "leftBlinker",
    "rightBlinker",
)
#: Which of them are booleans.
BOOLEAN_COLUMNS = ("brakePressed", "gasPressed", "leftBlinker", "rightBlinker")


@dataclass(frozen=True, eq=False)
class EgoSnapshots:
    """Every usable row of a snapshot table, in file order (see the module docstring)."""

    ids: tuple[str, ...]
    #: The frame (timestamp, ms) each row is played as.
    timestamps: npt.NDArray[np.int64]  # (R,)
    #: Each row's position among the table file's data rows (0 = the first).
    file_rows: npt.NDArray[np.int64]  # (R,)
    realised: FloatArray  # (R, 6, 3)
    predicted: FloatArray  # (R, 6, 3)
    vehicle: Mapping[str, FloatArray] = field(default_factory=dict)  # column -> (R,)
    gear: tuple[str, ...] = ()
    #: The submission file the predicted paths came from ("" = none).
    submission: str = ""

    def __len__(self) -> int:
        return len(self.ids)

    def row_at(self, timestamp_ms: int) -> int | None:
        """The row played at ``timestamp_ms`` (None: no row there)."""
        row = int(np.searchsorted(self.timestamps, timestamp_ms))
        found = row < len(self.timestamps) and int(self.timestamps[row]) == timestamp_ms
        return row if found else None

    @property
    def has_truth(self) -> bool:
        """Whether any row has a realised path (a train table; a test table has none)."""
        return bool(np.isfinite(self.realised).any())

    @property
    def has_prediction(self) -> bool:
        return bool(np.isfinite(self.predicted).any())


__all__ = [
    "BOOLEAN_COLUMNS",
    "HORIZONS_S",
    "TARGET_COLUMNS",
    "VEHICLE_COLUMNS",
    "EgoSnapshots",
]
