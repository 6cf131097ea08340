"""atmaCup #18 tables synthesised from the data description (no real sample is public).

``write_table(folder, rows)`` writes ``train_features.csv`` (with the 18 target columns) or
``test_features.csv`` (without) in the competition's column order, and
``traffic_lights/{ID}.json`` per row; ``write_submission`` writes a submission in the
competition's 18-column format (optionally with an ID column). :data:`ROWS` are three rows
whose every value is chosen by hand:

- row 0 (scene ``0a7d…82``, 32 s): 10 m/s in drive, left blinker on, gas pressed; the path
  straight ahead at 10 m/s (x = 5, 10 … 30 m) drifting 0.1 m a step to the LEFT (y =
  +0.1 … +0.6 in the table's right-handed frame) and 0.01 m a step up; two lights seen
  (green, red);
- row 1 (same scene, 42 s): parked, no light seen (an empty list); the path all zeros;
- row 2 (scene ``ffff…ff``, 10 s): reversing at 2.5 m/s (x = −1.25 … −7.5), brake
  pressed, right blinker on; one arrow light (left).

``big_table(n)`` gives n rows (scenes of 40 rows, ten seconds apart) for the benchmark.
"""

from __future__ import annotations

import csv
import json
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

TRAIN = "train_features.csv"
TEST = "test_features.csv"
LIGHTS = "traffic_lights"
#: The table's columns in the competition's order, before the targets.
FEATURE_COLUMNS = (
    "ID",
    "vEgo",
    "aEgo",
    "steeringAngleDeg",
    "steeringTorque",
    "brake",
    "brakePressed",
    "gas",
    "gasPressed",
    "gearShifter",
    "leftBlinker",
    "rightBlinker",
)
TARGETS = tuple(f"{axis}_{n}" for n in range(6) for axis in "xyz")

Path3 = tuple[tuple[float, float, float], ...]


@dataclass(frozen=True)
class Light:
    """One traffic-light detection as the JSON file writes it."""

    index: int
    kind: str
    bbox: tuple[float, float, float, float]

    def document(self) -> dict[str, object]:
        return {"index": self.index, "class": self.kind, "bbox": list(self.bbox)}


@dataclass(frozen=True)
class Row:
    """One table row: the CAN fields, the realised path (table frame, 6 × (x, y, z)) and
    the lights (None: no file)."""

    ident: str
    v_ego: float
    a_ego: float
    steering_deg: float
    steering_torque: float
    brake: float
    brake_pressed: bool
    gas: float
    gas_pressed: bool
    gear: str
    left_blinker: bool
    right_blinker: bool
    path: Path3
    lights: tuple[Light, ...] | None = field(default=())

    def features(self) -> list[str]:
        return [
            self.ident,
            repr(self.v_ego),
            repr(self.a_ego),
            repr(self.steering_deg),
            repr(self.steering_torque),
            repr(self.brake),
            str(self.brake_pressed),
            repr(self.gas),
            str(self.gas_pressed),
            self.gear,
            str(self.left_blinker),
            str(self.right_blinker),
        ]


def _straight(step: tuple[float, float, float]) -> Path3:
    return tuple((step[0] * n, step[1] * n, step[2] * n) for n in range(1, 7))


SCENE_A = "0a7d64c1e7fda174fc26c7cedd49d782"
SCENE_B = "ffffffffffffffffffffffffffffffff"
ROWS = (
    Row(
        f"{SCENE_A}_320",
        10.0,
        0.5,
        5.0,
        -0.2,
        0.0,
        False,
        0.3,
        True,
        "drive",
        True,
        False,
        _straight((5.0, 0.1, 0.01)),
        (
            Light(1, "green", (52.0, 0.5, 55.0, 2.5)),
            Light(2, "red", (26.5, 1.5, 29.5, 3.5)),
        ),
    ),
    Row(
        f"{SCENE_A}_420",
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        False,
        0.0,
        False,
        "park",
        False,
        False,
        _straight((0.0, 0.0, 0.0)),
        (),
    ),
    Row(
        f"{SCENE_B}_100",
        2.5,
        -0.1,
        -30.0,
        1.5,
        0.4,
        True,
        0.0,
        False,
        "reverse",
        False,
        True,
        _straight((-1.25, 0.0, 0.0)),
        (Light(1, "left", (10.0, 20.0, 12.0, 24.0)),),
    ),
)


def write_table(
    folder: Path, rows: Sequence[Row] = ROWS, train: bool = True, lights: bool = True
) -> Path:
    """The table (and its traffic-light files) in ``folder``; the table's path."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / (TRAIN if train else TEST)
    with path.open("w", newline="", encoding="utf-8") as out:
        writer = csv.writer(out)
        writer.writerow([*FEATURE_COLUMNS, *(TARGETS if train else ())])
        for row in rows:
            targets = [repr(v) for point in row.path for v in point] if train else []
            writer.writerow([*row.features(), *targets])
    if lights:
        directory = folder / LIGHTS
        directory.mkdir(exist_ok=True)
        for row in rows:
            if row.lights is not None:
                document = [light.document() for light in row.lights]
                (directory / f"{row.ident}.json").write_text(json.dumps(document))
    return path


def write_submission(path: Path, paths: Iterable[Path3], ids: Sequence[str] | None = None) -> Path:
    """A submission of ``paths`` (table frame), one row each; with ``ids`` an ID column
    first."""
    with path.open("w", newline="", encoding="utf-8") as out:
        writer = csv.writer(out)
        writer.writerow([*(["ID"] if ids is not None else []), *TARGETS])
        for n, points in enumerate(paths):
            values = [repr(v) for point in points for v in point]
            writer.writerow([*([ids[n]] if ids is not None else []), *values])
    return path


def big_table(count: int, lights_every: int = 1) -> list[Row]:
    """``count`` rows: scenes of 40 rows 10 s apart, speeds cycling 0…29 m/s, one green
    light on every ``lights_every``-th row (an empty list on the others)."""
    out: list[Row] = []
    for n in range(count):
        scene, step = divmod(n, 40)
        speed = float(n % 30)
        lights = (Light(1, "green", (50.0, 1.0, 53.0, 3.0)),) if n % lights_every == 0 else ()
        out.append(
            Row(
                f"{scene:032x}_{100 * (step + 1)}",
                speed,
                0.1,
                1.5,
                0.0,
                0.0,
                False,
                0.2,
                True,
                "drive",
                False,
                False,
                _straight((speed * 0.5, 0.01, 0.0)),
                lights,
            )
        )
    return out
