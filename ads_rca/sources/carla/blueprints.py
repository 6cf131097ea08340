"""Half extents of CARLA 0.9.15 blueprints: what a CARLA run leaves out of its telemetry.

The experiment client records each actor's blueprint (``type_id``) but not its bounding
box; the rules measure clearances between boxes, so a CARLA run's boxes come from this
table: ``actor.bounding_box.extent`` (x forward, y right, z up; HALF sizes, metres) of each
blueprint spawned in a CARLA 0.9.15 server, rounded to the millimetre. Every extent taken
from here is *assumed* (the run's capability record says so); a blueprint not listed gets
its class default and is named in the record.
"""

from __future__ import annotations

from collections.abc import Mapping

Extent = tuple[float, float, float]

BLUEPRINT_EXTENTS: Mapping[str, Extent] = {
    "vehicle.audi.a2": (1.853, 0.894, 0.775),
    "vehicle.audi.etron": (2.428, 1.016, 0.825),
    "vehicle.audi.tt": (2.091, 0.997, 0.693),
    "vehicle.bmw.grandtourer": (2.306, 1.121, 0.834),
    "vehicle.chevrolet.impala": (2.679, 1.017, 0.705),
    "vehicle.citroen.c3": (1.994, 0.925, 0.809),
    "vehicle.dodge.charger_2020": (2.504, 0.941, 0.767),
    "vehicle.dodge.charger_police": (2.487, 1.019, 0.771),
    "vehicle.dodge.charger_police_2020": (2.619, 0.965, 0.819),
    "vehicle.ford.crown": (2.683, 0.900, 0.787),
    "vehicle.ford.mustang": (2.359, 0.947, 0.650),
    "vehicle.jeep.wrangler_rubicon": (1.933, 0.953, 0.939),
    "vehicle.lincoln.mkz_2017": (2.451, 1.064, 0.755),
    "vehicle.lincoln.mkz_2020": (2.446, 0.918, 0.745),
    "vehicle.mercedes.coupe": (2.513, 1.076, 0.825),
    "vehicle.mercedes.coupe_2020": (2.337, 0.906, 0.721),
    "vehicle.micro.microlino": (1.104, 0.740, 0.688),
    "vehicle.mini.cooper_s": (1.903, 0.985, 0.738),
    "vehicle.mini.cooper_s_2021": (2.276, 1.049, 0.884),
    "vehicle.nissan.micra": (1.817, 0.923, 0.751),
    "vehicle.nissan.patrol": (2.302, 0.966, 0.927),
    "vehicle.nissan.patrol_2021": (2.783, 1.075, 1.023),
    "vehicle.seat.leon": (2.096, 0.908, 0.737),
    "vehicle.tesla.model3": (2.396, 1.082, 0.744),
    "vehicle.toyota.prius": (2.257, 1.003, 0.762),
    "vehicle.carlamotors.carlacola": (2.602, 1.313, 1.234),
    "vehicle.carlamotors.european_hgv": (3.968, 1.446, 1.731),
    "vehicle.carlamotors.firetruck": (4.234, 1.446, 1.914),
    "vehicle.tesla.cybertruck": (3.137, 1.195, 1.049),
    "vehicle.ford.ambulance": (3.183, 1.176, 1.216),
    "vehicle.mercedes.sprinter": (2.958, 0.994, 1.280),
    "vehicle.volkswagen.t2": (2.240, 1.035, 1.019),
    "vehicle.volkswagen.t2_2021": (2.221, 0.887, 0.994),
    "vehicle.mitsubishi.fusorosa": (5.136, 1.972, 2.126),
    "vehicle.harley-davidson.low_rider": (1.175, 0.383, 0.825),
    "vehicle.kawasaki.ninja": (1.022, 0.398, 0.762),
    "vehicle.vespa.zx125": (0.909, 0.433, 0.795),
    "vehicle.yamaha.yzf": (1.095, 0.433, 0.765),
    "vehicle.bh.crossbike": (0.755, 0.433, 0.806),
    "vehicle.diamondback.century": (0.828, 0.291, 0.810),
    "vehicle.gazelle.omafiets": (0.922, 0.330, 0.888),
}

#: Adult pedestrians (43 of the 51 walker blueprints); children are listed below.
ADULT_WALKER: Extent = (0.188, 0.188, 0.930)
_CHILD_WALKERS: Mapping[str, Extent] = {
    **{f"walker.pedestrian.{n:04d}": (0.250, 0.250, 0.550) for n in (9, 10, 11, 48, 49)},
    **{f"walker.pedestrian.{n:04d}": (0.188, 0.188, 0.650) for n in (12, 13, 14)},
}

#: A vehicle blueprint not in the table: the median of the 25 passenger cars above.
DEFAULT_VEHICLE: Extent = (2.337, 0.966, 0.767)

CLASS_DEFAULTS: Mapping[str, Extent] = {"vehicle": DEFAULT_VEHICLE, "walker": ADULT_WALKER}


def blueprint_extent(type_id: str, kind: str) -> tuple[Extent, bool]:
    """The half extent of blueprint ``type_id`` of class ``kind`` (``vehicle`` or
    ``walker``), and whether the table knows it (else the class default)."""
    known = BLUEPRINT_EXTENTS.get(type_id) or _CHILD_WALKERS.get(type_id)
    if known is not None:
        return known, True
    if kind == "walker" and type_id.startswith("walker.pedestrian.") and type_id[18:].isdigit():
        number = int(type_id[18:])
        if 1 <= number <= 51:
            return ADULT_WALKER, True
    return CLASS_DEFAULTS[kind], False
