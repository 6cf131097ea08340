"""The scenario families: a SUMO network, dense traffic, and one partner's manoeuvre.

Every family draws its parameters from a seeded generator, builds its network with
``netconvert`` (:mod:`sumo_world.networks`), fills it with flows of SUMO vehicles (Krauss
car-following with driver imperfection σ = 0.5, LC2013 lane changing, speed factors spread
±10 %, 1100…1600 vehicles an hour a lane), inserts the ego on its route (never next to the
oncoming lanes, where our stack's noisy predictions of oncoming cars make it brake for
ghosts) and, through a :class:`~sumo_world.record.Director`, makes one road user the partner:

- ``curve``: the ego's leader brakes hard (4.5…7 m/s², SUMO's own constant braking to a stop)
  once it is 30…70 % along a curve of radius 80…200 m (turning 45…90°, left or right);
- ``merge``: a car put on the on-ramp so that it reaches the acceleration lane 0.8…2.5 s ahead
  of the ego and 3…6 m/s slower; LC2013's own strategic change (``lcAssertive`` 8) merges it
  into the ego's lane; the scene is kept when it becomes the ego's leader within 25 m;
- ``intersection``: an oncoming car turns left across the ego's path on the junction's
  internal arc (60 %), or a car from the minor road crosses straight (40 %), at a constant
  6…10 m/s and ignoring the ego's right of way (``speedMode`` 0b110111), timed to reach the
  conflict point 0.6 s before to 0.2 s after our ego would; it is placed only when the ego
  has no leader within 2 s (one would meet the partner first); the minor road carries no
  other traffic (cars waiting at its stop line are ghosts to our predictor);
- ``dense``: in four lanes of dense traffic, once the ego has driven 120…350 m, the first car
  beside it in a neighbouring lane, 0.5…10 m ahead and 2…8 m/s slower, is asked over TraCI to
  change into the ego's lane; LC2013 performs the change over ``--lanechange.duration``
  (2…3.5 s), avoiding only immediate collisions: a sharp cut-in;
- ``crossing``: a pedestrian standing at a zebra crossing (pedestrians have priority) sets
  off at 1.2…2 m/s, timed to reach the ego's lane 0.3 s before to 0.4 s after our ego would;
  SUMO's striping model walks it across the walking area and the crossing. As the
  synthesiser's ``pedestrian_crossing``, nothing else comes within a lane of the ego's path:
  no car on its side of the road (a leader would stop for the pedestrian first, a car
  beside it is a ghost conflict), walkers only on the far sidewalk.

What is SUMO's: the road geometry, every trajectory (the partner's manoeuvre included, once
asked for), the traffic's reactions. What is ours: the trigger (which road user, when, and
for ``intersection``, ``merge`` and ``crossing`` where the partner is placed so that it
meets our ego), and the parameters above.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import ModuleType
from typing import Any

import numpy as np

from sumo_world import networks
from sumo_world.geometry import FloatArray
from sumo_world.record import EGO, PARTNER, STEP_S, Director, Event, Refused

FAMILIES = ("curve", "merge", "intersection", "dense", "crossing")
#: Car models (length, width, height) as the synthesiser's CAR_EXTENTS, doubled.
CARS = ((4.90, 2.13, 1.51), (4.79, 2.16, 1.49), (4.55, 2.01, 1.53), (5.03, 2.15, 1.64))
EGO_SIZE = CARS[0]


#: Traffic that yields to a pedestrian on a crossing only once it is within 3 m of its lane
#: (``jmCrossingGap``, SUMO's default 10 m): the oncoming cars do not brake ahead of the ego
#: while the pedestrian is still on the ego's side.
LATE_YIELD = 'jmCrossingGap="3"'
#: A pedestrian walking at exactly the speed it is given (no spread of speed factors).
WALKER = (
    '<vType id="walker" vClass="pedestrian" length="0.5" width="0.5" height="1.8" '
    'speedFactor="1" speedDev="0"/>'
)


def vtypes(assertive: float = 5.0, ego_factor: float = 1.0, traffic: str = "") -> str:
    """The vehicle and pedestrian types every family uses (``traffic``: attributes added to
    every car type)."""
    lines = []
    extra = f" {traffic}" if traffic else ""
    for n, (length, width, height) in enumerate(CARS):
        lines.append(
            f'<vType id="car{n}" length="{length}" width="{width}" height="{height}" '
            'accel="2.6" decel="4.5" emergencyDecel="9" sigma="0.5" tau="1.0" '
            f'speedFactor="normc(1,0.1,0.7,1.3)" lcAssertive="1.3"{extra}/>'
        )
    lines.append('<vTypeDistribution id="cars" vTypes="car0 car1 car2 car3"/>')
    length, width, height = EGO_SIZE
    lines.append(
        f'<vType id="ego" length="{length}" width="{width}" height="{height}" accel="2.0" '
        f'decel="8" emergencyDecel="9" sigma="0" tau="1.0" speedFactor="{ego_factor:.3f}" '
        'speedDev="0"/>'
    )
    length, width, height = CARS[2]
    lines.append(
        f'<vType id="partner" length="{length}" width="{width}" height="{height}" '
        'accel="2.6" decel="4.5" emergencyDecel="9" sigma="0" tau="1.0" speedFactor="1" '
        f'speedDev="0" lcAssertive="{assertive:.2f}" lcCooperative="0" lcSpeedGain="3"/>'
    )
    lines.append(
        '<vType id="ped" vClass="pedestrian" length="0.5" width="0.5" height="1.8" '
        'speed="1.3" speedFactor="normc(1,0.15,0.6,1.4)"/>'
    )
    return "\n".join(lines)


def flow(name: str, route: str, per_lane: float, lanes: int, lane: str = "random") -> str:
    return (
        f'<flow id="{name}" type="cars" route="{route}" begin="0" end="{600}" '
        f'vehsPerHour="{per_lane * lanes:.0f}" departLane="{lane}" departSpeed="max"/>'
    )


def demand(
    body: list[str], assertive: float = 5.0, ego_factor: float = 1.0, traffic: str = ""
) -> str:
    types = vtypes(assertive, ego_factor, traffic)
    return "<routes>\n" + types + "\n" + "\n".join(body) + "\n</routes>\n"


@dataclass
class Setup:
    """A family instance: its network and its director, and the parameters drawn."""

    net: networks.Network
    director: Director
    params: dict[str, float | str]
    options: tuple[str, ...] = ()


class CurveBraking(Director):
    """The ego's leader brakes hard mid-curve."""

    def __init__(self, rng: np.random.Generator, curve_length: float, flows: list[str]) -> None:
        self.ego_route = ("in", "curve", "out")
        self.ego_lane = int(rng.integers(0, 2))  # not next to the oncoming lanes
        self.ego_depart_s = float(rng.uniform(25.0, 45.0))
        self.decel = float(rng.uniform(4.5, 7.0))
        self.at = float(rng.uniform(0.3, 0.7)) * curve_length
        self.flows = flows

    def routes(self) -> str:
        return demand(['<route id="r_in" edges="in curve out"/>', *self.flows])

    def step(self, traci: ModuleType, k: int) -> Event | None:
        road = traci.vehicle.getRoadID(EGO)
        if road == "out":
            raise Refused("the ego left the curve without a leader to brake")
        leader = traci.vehicle.getLeader(EGO, 60.0)
        if not leader or leader[0] == "":
            return None
        name, gap = leader
        if (
            traci.vehicle.getRoadID(name) != "curve"
            or traci.vehicle.getLanePosition(name) < self.at
        ):
            return None
        if not 4.0 <= gap <= 35.0 or traci.vehicle.getSpeed(EGO) < 6.0:
            return None
        self.do(traci, k, "vehicle", "setLaneChangeMode", name, 0)
        self.do(traci, k, "vehicle", "setDecel", name, self.decel)
        self.do(traci, k, "vehicle", "setEmergencyDecel", name, max(9.0, self.decel))
        self.do(traci, k, "vehicle", "setSpeed", name, 0.0)
        return Event(name, k, "stale")


class DenseCutIn(Director):
    """A slower car beside and just ahead of the ego changes into its lane (LC2013)."""

    def __init__(self, rng: np.random.Generator, flows: list[str]) -> None:
        self.ego_route = ("a", "b", "c")
        self.ego_lane = int(rng.integers(1, 3))
        self.ego_depart_s = float(rng.uniform(30.0, 50.0))
        self.side = int(rng.choice([-1, 1]))  # which side is looked at first (+1: left)
        self.gap = (float(rng.uniform(0.5, 2.0)), float(rng.uniform(6.0, 10.0)))
        self.after_m = float(rng.uniform(120.0, 350.0))
        self.flows = flows
        self.lane_index = -1

    def routes(self) -> str:
        return demand(['<route id="r_a" edges="a b c"/>', *self.flows])

    def step(self, traci: ModuleType, k: int) -> Event | None:
        if traci.vehicle.getDistance(EGO) < self.after_m:
            return None
        if traci.vehicle.getRoadID(EGO) == "c" and traci.vehicle.getLanePosition(EGO) > 300:
            raise Refused("no car to cut in beside the ego")
        modes = (2, 3) if self.side > 0 else (3, 2)  # leaders on the left / right
        v_ego = traci.vehicle.getSpeed(EGO)
        beside = [n for mode in modes for n in traci.vehicle.getNeighbors(EGO, mode)]
        for name, gap in beside:
            if not self.gap[0] <= gap <= self.gap[1]:
                continue
            if not 2.0 <= v_ego - traci.vehicle.getSpeed(name) <= 8.0:
                continue
            self.lane_index = traci.vehicle.getLaneIndex(EGO)
            # Only TraCI's request, executed avoiding immediate collisions.
            self.do(traci, k, "vehicle", "setLaneChangeMode", name, 1 << 8)
            self.do(traci, k, "vehicle", "changeLane", name, self.lane_index, 8.0)
            return Event(name, k, "keep_lane")
        return None

    def check(self, traci: ModuleType, k: int, event: Event) -> None:
        if (
            k - event.step == int(4.0 / STEP_S)
            and event.partner in traci.vehicle.getIDList()
            and traci.vehicle.getLaneIndex(event.partner) != self.lane_index
        ):
            raise Refused("LC2013 did not change the partner's lane")


class RampMerge(Director):
    """A car from the on-ramp merges into the ego's lane just ahead of it (LC2013)."""

    observed = True
    timed = True

    def marks(self, sumolib: Any) -> tuple[FloatArray, FloatArray]:
        from sumo_world.scene import net_of

        net = net_of(str(self.net), sumolib)
        ramp = np.asarray(net.getLane("r1_0").getShape(), dtype=np.float64)
        main = np.asarray(net.getLane("m2_1").getShape(), dtype=np.float64)
        return np.array([main[0, 0], main[0, 1]]), ramp[-1]

    def shift(self, seconds: float) -> None:
        _shift_position(self, seconds * self.partner_speed)

    def __init__(
        self, rng: np.random.Generator, ramp_length: float, ramp_speed: float, flows: list[str]
    ) -> None:
        self.ego_route = ("m1", "m2", "m3")
        self.ego_lane = 0
        self.ego_depart_s = float(rng.uniform(25.0, 45.0))
        self.insert_at = float(rng.uniform(90.0, 140.0))  # ego's distance to the ramp's end
        self.lead = float(rng.uniform(0.8, 2.5))  # s the partner is ahead at the ramp's end
        self.slower = float(rng.uniform(3.0, 6.0))
        self.late = -self.lead
        self.ramp_length = ramp_length
        self.ramp_speed = ramp_speed
        self.flows = flows
        self.inserted = -1
        self.partner_speed = 0.0
        self.capped = False
        self.change_s = 3.0  # the lane-change duration (set by :func:`build`)

    def routes(self) -> str:
        return demand(
            [
                '<route id="r_m" edges="m1 m2 m3"/>',
                '<route id="r_r" edges="r1 m2 m3"/>',
                *self.flows,
            ],
            assertive=8.0,
        )

    def step(self, traci: ModuleType, k: int) -> Event | None:
        road = traci.vehicle.getRoadID(EGO)
        if self.inserted < 0:
            if road != "m1":
                raise Refused("the ego passed the ramp before the partner could be placed")
            to_go = traci.lane.getLength("m1_0") - traci.vehicle.getLanePosition(EGO)
            if to_go > self.insert_at:
                return None
            v_ego = max(traci.vehicle.getSpeed(EGO), 5.0)
            self.partner_speed = max(min(v_ego - self.slower, self.ramp_speed), 5.0)
            t_arrive = to_go / v_ego - self.lead
            pos = self.ramp_length - self.partner_speed * t_arrive
            if pos < 5.0:
                raise Refused("the ramp is too short to place the partner")
            speed = f"{self.partner_speed:.2f}"
            args = (PARTNER, "r_r", "partner", "now", "0", f"{pos:.2f}", speed)
            self.do(traci, k, "vehicle", "add", *args)
            self.inserted = k
            return None
        if PARTNER not in traci.vehicle.getIDList():
            if k - self.inserted > 40:
                raise Refused("the partner could not be inserted on the ramp")
            return None
        if not self.capped:
            self.do(traci, k, "vehicle", "setMaxSpeed", PARTNER, self.partner_speed)
            self.capped = True
        return self.detect(traci, k)

    def detect(self, traci: ModuleType, k: int) -> Event | None:
        if PARTNER not in traci.vehicle.getIDList():
            return None
        road = traci.vehicle.getRoadID(EGO)
        lane = traci.vehicle.getLaneID(PARTNER)
        if lane.startswith("m2_") and lane != "m2_0":
            leader = traci.vehicle.getLeader(EGO, 40.0)
            if not leader or leader[0] != PARTNER or leader[1] > 25.0:
                raise Refused("the partner merged elsewhere than just ahead of the ego")
            # SUMO moves it to the new lane half-way through the change.
            return Event(PARTNER, k - round(self.change_s / 2 / STEP_S), "keep_lane")
        if road == "m3":
            raise Refused("the partner did not merge in front of the ego")
        return None


class Junction(Director):
    """A car turns left across (or crosses) the ego's path against its right of way, at a
    constant speed timed to reach the conflict point as the ego does."""

    timed = True
    observed = True

    def __init__(self, rng: np.random.Generator, arm: float, flows: list[str]) -> None:
        self.ego_route = ("wc", "ce")
        self.ego_lane = 0
        self.ego_depart_s = float(rng.uniform(25.0, 45.0))
        self.ego_factor = float(rng.uniform(0.75, 0.9))  # a calm driver: gaps open ahead
        self.kind = "left" if rng.random() < 0.6 else "cross"
        self.route = ("ec", "cs") if self.kind == "left" else ("sc", "cn")
        self.partner_lane = 1 if self.kind == "left" else int(rng.integers(0, 2))
        self.insert_eta = float(rng.uniform(8.0, 9.5))  # s before the ego reaches the conflict
        self.late = float(rng.uniform(-0.6, 0.2))  # s the partner is later there
        speeds = (6.0, 8.5) if self.kind == "left" else (7.0, 10.0)
        self.partner_speed = float(rng.uniform(*speeds))
        self.commit_eta = 5.5  # s before the conflict: its course is set (the trigger)
        self.arm = arm
        self.flows = flows
        self.inserted = -1
        self.conflict: tuple[float, float] | None = None  # along ego's, partner's lines

    def routes(self) -> str:
        body = [f'<route id="r_p" edges="{" ".join(self.route)}"/>']
        for a, b in (("w", "e"), ("e", "w"), ("s", "n"), ("n", "s")):
            body.append(f'<route id="r_{a}{b}" edges="{a}c c{b}"/>')
        body += self.flows
        return demand(body, ego_factor=self.ego_factor)

    def _lines(self) -> tuple[FloatArray, FloatArray]:
        from sumo_world.env import client_modules
        from sumo_world.scene import net_of, resample, route_polyline

        net = net_of(str(self.net), client_modules()[1])
        ego = resample(route_polyline(net, [f"wc_{self.ego_lane}"], self.ego_route), 0.25)
        other = resample(
            route_polyline(net, [f"{self.route[0]}_{self.partner_lane}"], self.route), 0.25
        )
        return ego, other

    def _conflict(self, traci: ModuleType) -> tuple[float, float]:
        """Where the partner's path crosses the ego lane's centre line: the arc length along
        each line (from the start of its first edge)."""
        ego, other = self._lines()
        d = np.hypot(ego[:, None, 0] - other[None, :, 0], ego[:, None, 1] - other[None, :, 1])
        i, j = np.unravel_index(int(np.argmin(d)), d.shape)
        return 0.25 * float(i), 0.25 * float(j)

    def marks(self, sumolib: Any) -> tuple[FloatArray, FloatArray]:
        ego, other = self._lines()
        assert self.conflict is not None
        i, j = int(self.conflict[0] / 0.25), int(self.conflict[1] / 0.25)
        return ego[i], other[j]

    def shift(self, seconds: float) -> None:
        _shift_position(self, seconds * self.partner_speed)

    def detect(self, traci: ModuleType, k: int) -> Event | None:
        if PARTNER not in traci.vehicle.getIDList() or self.conflict is None:
            return None
        if traci.vehicle.getRoadID(PARTNER) != self.route[0]:
            return Event(PARTNER, k, "frozen")
        to_go = self.conflict[1] - traci.vehicle.getLanePosition(PARTNER)
        if to_go / self.partner_speed > self.commit_eta:
            return None
        return Event(PARTNER, k, "frozen")

    def step(self, traci: ModuleType, k: int) -> Event | None:
        if self.conflict is None:
            self.conflict = self._conflict(traci)
        s_ego, s_partner = self.conflict
        if self.inserted < 0:
            if traci.vehicle.getRoadID(EGO) != "wc":
                raise Refused("the ego reached the junction before the partner was placed")
            v_ego = max(traci.vehicle.getSpeed(EGO), 3.0)
            eta = (s_ego - traci.vehicle.getLanePosition(EGO)) / v_ego
            if eta > self.insert_eta:
                return None
            leader = traci.vehicle.getLeader(EGO, 120.0)
            if leader and leader[0] and leader[1] < 2.0 * v_ego:
                # A leader this close would meet the partner first: wait for a gap.
                if eta < self.insert_eta - 3.0:
                    raise Refused("no gap in front of the ego to meet the partner")
                return None
            limit = traci.lane.getMaxSpeed(f"{self.route[0]}_0")
            self.partner_speed = min(self.partner_speed, limit)
            pos = s_partner - self.partner_speed * (eta + self.late)
            if pos < 5.0:
                raise Refused("the arm is too short to place the partner")
            lane, speed = str(self.partner_lane), f"{self.partner_speed:.2f}"
            args = (PARTNER, "r_p", "partner", "now", lane, f"{pos:.2f}", speed)
            self.do(traci, k, "vehicle", "add", *args)
            self.do(traci, k, "vehicle", "setSpeedMode", PARTNER, 0b110111)  # no right of way
            self.do(traci, k, "vehicle", "setLaneChangeMode", PARTNER, 0)
            self.do(traci, k, "vehicle", "setSpeed", PARTNER, self.partner_speed)
            self.inserted = k
            return None
        if PARTNER not in traci.vehicle.getIDList():
            if k - self.inserted > 40:
                raise Refused("the partner could not be inserted")
            return None
        return self.detect(traci, k)


@dataclass
class ZebraMarks:
    """Where the ego's centre (on its lane's centre line) and the pedestrian (on the crossing)
    meet, SUMO frame, and the pedestrian's way there from the kerb (m)."""

    ego: FloatArray
    walker: FloatArray
    walk_m: float


#: s the pedestrian first sets off before it is timed to: the replays move it later, which
#: only lengthens the window's lead-in (an earlier start could leave the window the first
#: run fixed).
EARLY_S = 1.5
#: m before its sidewalk's end the pedestrian stands.
KERB_M = 1.0


class ZebraCrossing(Director):
    """A pedestrian standing at a zebra crossing starts across as the ego approaches.

    As in the synthesiser's ``pedestrian_crossing``, no other road user is within a lane of
    the ego's path (its background keeps two lanes or 8.2 m away): the ego drives the middle
    of three lanes with no other car on its side of the road (a leader would stop for the
    pedestrian first; a car beside it, slowing for the pedestrian or not, is a ghost conflict
    to our noisy predictor: 1.4 m of clearance against the planner's 1 m margin), the
    oncoming traffic is 7 m or more away, and walkers use only the far sidewalk (the near
    one is 6.9 m from the ego lane's centre, where our predictor's noise on them made the
    ego brake hard). The pedestrian stands still on the kerb (speed 0: a waiting stage
    would draw it 3 m off the sidewalk and jump it back as it sets off) until its walk,
    measured along its way across the walking area, is timed to meet the ego.
    """

    persons = True
    timed = True
    observed = True

    def __init__(self, rng: np.random.Generator, flows: list[str]) -> None:
        self.ego_route = ("wc", "ce")
        self.ego_lane = 2  # the middle lane (0 is the sidewalk)
        self.ego_factor = float(rng.uniform(0.75, 0.9))  # a calm driver
        self.ego_depart_s = float(rng.uniform(25.0, 45.0))
        self.insert_at = float(rng.uniform(140.0, 170.0))
        self.walk_speed = float(rng.uniform(1.2, 2.0))
        self.late = float(rng.uniform(-0.3, 0.4))
        self.flows = flows
        self.start = -1  # the step it sets off
        self.zebra: ZebraMarks | None = None

    def routes(self) -> str:
        body = [
            '<route id="r_we" edges="wc ce"/>',
            '<route id="r_ew" edges="ec cw"/>',
            WALKER,
            *self.flows,
        ]
        for n, (a, b) in enumerate((("ec", "cw"), ("cw", "ec"))):  # the far sidewalk
            body.append(
                f'<personFlow id="pf{n}" type="ped" begin="0" end="600" period="{8 + 2 * n}">'
                f'<walk from="{a}" to="{b}"/></personFlow>'
            )
        return demand(body, ego_factor=self.ego_factor, traffic=LATE_YIELD)

    def _marks(self, sumolib: Any) -> ZebraMarks:
        """Where the ego and the pedestrian meet, and the pedestrian's way there (computed
        once)."""
        from sumo_world.scene import net_of, resample, route_polyline

        if self.zebra is not None:
            return self.zebra
        net = net_of(str(self.net), sumolib)
        ego = resample(route_polyline(net, [f"wc_{self.ego_lane}"], self.ego_route), 0.25)
        crossing = next(e for e in net.getEdges(withInternal=True) if e.getFunction() == "crossing")
        shape = np.asarray(crossing.getLanes()[0].getShape(), dtype=np.float64)
        walk = resample(shape, 0.1)
        d = np.hypot(ego[:, None, 0] - walk[None, :, 0], ego[:, None, 1] - walk[None, :, 1])
        i, j = np.unravel_index(int(np.argmin(d)), d.shape)
        kerb = net.getLane("wc_0")
        stand = np.asarray(
            sumolib.geomhelper.positionAtShapeOffset(kerb.getShape(), kerb.getLength() - KERB_M),
            dtype=np.float64,
        )
        # From the kerb across the walking area to the crossing's near end, then along it.
        ends = shape[[0, -1]]
        near = ends[int(np.argmin(np.hypot(*(ends - stand).T)))]
        walk_m = float(np.hypot(*(near - stand)) + np.hypot(*(walk[j] - near)))
        self.zebra = ZebraMarks(ego[i], walk[j], walk_m)
        return self.zebra

    def marks(self, sumolib: Any) -> tuple[FloatArray, FloatArray]:
        zebra = self._marks(sumolib)
        return zebra.ego, zebra.walker

    def step(self, traci: ModuleType, k: int) -> Event | None:
        if self.start < 0:
            if traci.vehicle.getRoadID(EGO) != "wc":
                raise Refused("the ego passed the crossing before the pedestrian was placed")
            from sumo_world.env import client_modules

            zebra = self._marks(client_modules()[1])
            # The road runs west to east: the ego's centre reaches its mark this far on.
            x_front = traci.vehicle.getPosition(EGO)[0]
            to_go = float(zebra.ego[0]) - x_front + EGO_SIZE[0] / 2
            if to_go > self.insert_at:
                return None
            v_ego = max(traci.vehicle.getSpeed(EGO), 5.0)
            wait = to_go / v_ego + self.late - zebra.walk_m / self.walk_speed - EARLY_S
            if wait < 2.8:
                raise Refused("the ego is too close to let the pedestrian wait")
            pos = traci.lane.getLength("wc_0") - KERB_M
            self.do(traci, k, "person", "add", PARTNER, "wc", pos, -3, "walker")
            self.do(traci, k, "person", "appendWalkingStage", PARTNER, ["wc", "cw"], 5.0)
            self.do(traci, k, "person", "setSpeed", PARTNER, 0.0)
            self.start = k + round(wait / STEP_S)
            return None
        if k == self.start:
            self.do(traci, k, "person", "setSpeed", PARTNER, self.walk_speed)
        return self.detect(traci, k)

    def detect(self, traci: ModuleType, k: int) -> Event | None:
        if PARTNER not in traci.person.getIDList():
            return None
        if traci.person.getSpeed(PARTNER) > 0.2:  # it has set off
            return Event(PARTNER, k, "keep_lane")
        return None

    def shift(self, seconds: float) -> None:
        placed = next(k for k, _, method, _ in self.actions if method == "add")
        for n, (k, domain, method, args) in enumerate(self.actions):
            if method == "setSpeed" and float(args[1]) > 0.0:
                later = max(k + round(seconds / STEP_S), placed + round(0.5 / STEP_S))
                self.actions[n] = (later, domain, method, args)


def _shift_position(director: Director, metres: float) -> None:
    """Insert the partner ``metres`` further back on its route (arriving later)."""
    for n, (k, domain, method, args) in enumerate(director.actions):
        if method == "add":
            pos = float(args[5]) - metres
            if pos < 1.0:
                raise Refused("the partner would start before its route does")
            director.actions[n] = (k, domain, method, (*args[:5], f"{pos:.2f}", *args[6:]))


def build(family: str, rng: np.random.Generator) -> Setup:
    """A ``family`` instance drawn from ``rng``."""
    per_lane = float(rng.uniform(1100.0, 1600.0))
    duration = float(rng.uniform(2.0, 3.5))
    options: tuple[str, ...] = ("--lanechange.duration", f"{duration:.2f}")
    params: dict[str, float | str] = {"veh_per_hour_lane": round(per_lane)}
    if family == "curve":
        radius = float(rng.uniform(80.0, 200.0))
        angle = float(rng.choice([-1.0, 1.0])) * float(rng.uniform(0.5, 1.0)) * math.pi / 2
        speed = float(min(rng.uniform(12.5, 16.7), math.sqrt(2.2 * radius)))
        net = networks.curve(radius, angle, speed)
        flows = [
            flow("f_in", "r_in", per_lane, 3),
            '<route id="r_back" edges="-out -curve -in"/>',
            flow("f_back", "r_back", per_lane * 0.8, 2),
        ]
        director: Director = CurveBraking(rng, abs(angle) * radius, flows)
        params |= {"radius_m": round(radius, 1), "turn_deg": round(math.degrees(angle), 1)}
        params |= {"speed_limit": round(speed, 2)}
    elif family == "merge":
        speed = float(rng.uniform(15.0, 19.4))
        ramp_speed = float(rng.uniform(11.0, 13.9))
        accel = float(rng.uniform(150.0, 250.0))
        net = networks.merge(accel, speed, ramp_speed)
        flows = [
            flow("f_m", "r_m", per_lane, 2),
            flow("f_r", "r_r", per_lane * 0.2, 1, "0"),
            '<route id="r_back" edges="-m3 -m2 -m1"/>',
            flow("f_back", "r_back", per_lane * 0.8, 2),
        ]
        director = ramp = RampMerge(rng, _ramp_length(), ramp_speed, flows)
        ramp.change_s = duration
        params |= {"accel_lane_m": round(accel, 1), "speed_limit": round(speed, 2)}
    elif family == "intersection":
        speed = float(rng.uniform(11.0, 13.9))
        net = networks.intersection(speed, speed * 0.8)
        flows = [
            flow("f_we", "r_we", per_lane * 0.7, 2),
            flow("f_ew", "r_ew", per_lane * 0.5, 2),
        ]
        junction = Junction(rng, 300.0, flows)
        director = junction
        params |= {"partner": junction.kind, "speed_limit": round(speed, 2)}
    elif family == "dense":
        speed = float(rng.uniform(13.9, 16.7))
        bend = float(rng.choice([-1.0, 1.0])) * float(rng.uniform(0.1, 0.3))
        net = networks.dense(speed, bend)
        flows = [
            flow("f_a", "r_a", per_lane * 1.1, 4),
            '<route id="r_back" edges="-c -b -a"/>',
            flow("f_back", "r_back", per_lane * 0.8, 3),
        ]
        director = DenseCutIn(rng, flows)
        params |= {"speed_limit": round(speed, 2)}
    elif family == "crossing":
        speed = float(rng.uniform(11.0, 13.9))
        net = networks.crossing(speed)
        flows = [flow("f_ew", "r_ew", per_lane * 0.3, 3)]  # only oncoming (see ZebraCrossing)
        director = zebra = ZebraCrossing(rng, flows)
        options += ("--pedestrian.striping.dawdling", "0")  # it walks at the speed it is given
        params |= {"speed_limit": round(speed, 2), "walk_speed": round(zebra.walk_speed, 2)}
    else:
        raise ValueError(f"unknown family {family!r}; choose from {', '.join(FAMILIES)}")
    params["lane_change_s"] = round(duration, 2)
    return Setup(net, director, params, options)


def _ramp_length() -> float:
    """The on-ramp's length (the shape :func:`networks.merge` draws)."""
    u = np.linspace(0.0, 1.0, 41)
    x, y = 320.0 * u, -95.0 * (1.0 - u) ** 2
    return float(np.hypot(np.diff(x), np.diff(y)).sum())
