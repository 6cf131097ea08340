"""Run SUMO headless over TraCI and record every road user around the ego at 20 Hz.

SUMO steps at 50 ms (``--step-length 0.05``), the log's frame, so nothing is resampled. The
ego is inserted on its route as an ordinary vehicle (no lane changes of its own, otherwise
SUMO's car-following model), so traffic reacts to it while recording. A context
subscription around the ego returns each step's positions and headings of the vehicles and
people within :data:`RADIUS`; a family's :class:`Director` watches the run and, at the
moment its event is due, makes one road user the partner (see :mod:`sumo_world.families`).
The recording ends :attr:`Director.after` steps after that event. A :class:`Replay` runs
the same scene again: the director's commands at their steps, SUMO's ego placed where our
stack's ego drove (``moveToXY``), so the traffic reacts to ours.
"""

from __future__ import annotations

import contextlib
import io
import itertools
import math
import os
import subprocess
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from sumo_world.env import Sumo, client
from sumo_world.geometry import FloatArray

STEP_S = 0.05
RADIUS = 230.0  # m around the ego that is recorded
MAX_TIME_S = 240.0  # a run that has not found its event by then is refused
EGO = "ego"
PARTNER = "partner"
_labels = itertools.count()


@dataclass
class Event:
    """The partner (a SUMO id), the step its conflicting behaviour starts, and the
    optimistic wrong motion model a prediction fault gives it."""

    partner: str
    step: int
    model: str


@dataclass
class Recording:
    """One SUMO run in SUMO's frame: per recorded step, every road user around the ego."""

    first_step: int  # the step of row 0
    ids: list[str]
    kinds: list[str]  # "vehicle" / "pedestrian"
    size: FloatArray  # (N, 2) length, width (m)
    front: FloatArray  # (K, N, 2) front-bumper positions (vehicles), positions (people); NaN
    angle: FloatArray  # (K, N) SUMO angle (deg, clockwise from north); NaN where absent
    ego_xy: FloatArray  # (K, 2) the SUMO ego's front bumper
    ego_angle: FloatArray  # (K,)
    ego_speed: FloatArray  # (K,)
    ego_lanes: list[str]  # the lanes the ego was on, in order (internal ones included)
    ego_route: tuple[str, ...]
    event: Event
    net: Path
    info: dict[str, Any] = field(default_factory=dict)

    def row(self, step: int) -> int:
        return step - self.first_step


class Refused(Exception):
    """A run whose event did not happen as the family needs it (the attempt is skipped)."""


@dataclass
class Replay:
    """A second run of the same scene: the director's commands of the first run at their
    steps, and the ego driven through ``track`` (step -> SUMO x, y, angle of its front
    bumper): where our stack's fault-free ego drove, so the traffic reacts to it."""

    actions: list[tuple[int, str, str, tuple[Any, ...]]]
    event: Event
    track: dict[int, tuple[float, float, float]]
    detect: bool = False  # the event is observed (re-detected), not commanded


class Director:
    """A family's script on top of SUMO's traffic: ego route and lane, the event.

    ``step`` is called after every simulation step once the ego drives; it returns the event
    when it happens (at most once) and may raise :class:`Refused`.
    """

    ego_route: tuple[str, ...] = ()
    ego_lane = 0
    ego_depart_s = 30.0
    after = 200  # steps recorded after the event
    persons = False
    #: Whether the event is observed in SUMO's own behaviour (re-detected on a replay).
    observed = False
    actions: list[tuple[int, str, str, tuple[Any, ...]]]
    net: Path  # set by :func:`run`

    def routes(self) -> str:
        raise NotImplementedError

    def step(self, traci: ModuleType, k: int) -> Event | None:
        raise NotImplementedError

    def detect(self, traci: ModuleType, k: int) -> Event | None:
        """An observed event (``observed`` families), on the first run and on a replay."""
        raise NotImplementedError

    #: Whether the partner is timed against the ego (its arrival can be shifted).
    timed = False
    #: s the partner should reach its mark after the ego reaches its own.
    late = 0.0

    def marks(self, sumolib: Any) -> tuple[FloatArray, FloatArray]:
        """Where the ego's centre and the partner's centre meet the conflict (SUMO frame)."""
        raise NotImplementedError

    def shift(self, seconds: float) -> None:
        """Make the partner reach its mark ``seconds`` later (its placing command changed)."""
        raise NotImplementedError

    def do(self, traci: Any, k: int, domain: str, method: str, *args: Any) -> None:
        """A command to SUMO, remembered so that a replay gives it at the same step."""
        if not hasattr(self, "actions"):
            self.actions = []
        self.actions.append((k, domain, method, args))
        getattr(getattr(traci, domain), method)(*args)

    def check(self, traci: ModuleType, k: int, event: Event) -> None:
        """Called every step after the event (may raise :class:`Refused`)."""


def run(
    sumo: Sumo,
    net: Path,
    director: Director,
    seed: int,
    options: tuple[str, ...] = (),
    replay: Replay | None = None,
) -> Recording:
    """Run SUMO on ``net`` with ``director``'s demand and record around the ego (a
    ``replay``: the first run's commands, the ego on the given track)."""
    traci, _ = client(sumo)
    tc = traci.constants
    folder = net.parent
    routes = folder / f"routes-{os.getpid()}-{next(_labels)}.rou.xml"
    routes.write_text(director.routes(), encoding="utf-8")
    command = [
        str(sumo.sumo),
        "--net-file",
        str(net),
        "--route-files",
        str(routes),
        "--step-length",
        f"{STEP_S}",
        "--seed",
        str(seed),
        "--no-step-log",
        "--no-warnings",
        "--duration-log.disable",
        "--collision.action",
        "warn",
        "--time-to-teleport",
        "-1",
        "--default.carfollowmodel",
        "Krauss",
        "--lanechange-output",
        os.devnull,
        *options,
    ]
    port = traci.getFreeSocketPort()
    process = subprocess.Popen(
        [*command, "--remote-port", str(port)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env=sumo.environment(),
    )
    try:
        with contextlib.redirect_stdout(io.StringIO()):  # the client's "Retrying" lines
            conn = traci.connect(port, 200, "localhost", process, 0.02)
        try:
            return _record(conn, tc, director, net, replay)
        except traci.exceptions.TraCIException as error:  # a command SUMO refused
            raise Refused(f"SUMO refused a command: {error}") from None
        finally:
            conn.close()
    finally:
        if process.poll() is None:
            process.kill()
        process.wait()
        routes.unlink(missing_ok=True)


def _record(conn: Any, tc: Any, director: Director, net: Path, replay: Replay | None) -> Recording:
    director.net = net
    conn.route.add("ego_route", list(director.ego_route))
    conn.vehicle.add(
        EGO,
        "ego_route",
        typeID="ego",
        depart=f"{director.ego_depart_s:.2f}",
        departLane=str(director.ego_lane),
        departSpeed="max",
    )
    variables = [tc.VAR_POSITION, tc.VAR_ANGLE]
    ego_vars = [tc.VAR_POSITION, tc.VAR_ANGLE, tc.VAR_SPEED, tc.VAR_LANE_ID]
    steps: list[dict[str, tuple[float, float, float]]] = []
    ego_rows: list[tuple[float, float, float, float]] = []
    lanes: list[str] = []
    sizes: dict[str, tuple[float, float, str]] = {}
    first = -1
    event: Event | None = None
    end = -1
    k = 0
    while True:
        conn.simulationStep()
        k += 1
        if k * STEP_S > MAX_TIME_S:
            raise Refused("no event before the time limit")
        if first < 0:
            if EGO not in conn.vehicle.getIDList():
                continue
            first = k
            conn.vehicle.setLaneChangeMode(EGO, 0)
            conn.vehicle.subscribe(EGO, ego_vars)
            conn.vehicle.subscribeContext(EGO, tc.CMD_GET_VEHICLE_VARIABLE, RADIUS, variables)
            if director.persons:
                conn.vehicle.subscribeContext(EGO, tc.CMD_GET_PERSON_VARIABLE, RADIUS, variables)
            continue  # subscriptions answer from the next step on
        ego = conn.vehicle.getSubscriptionResults(EGO)
        if not ego:
            raise Refused("the ego left the network before its event")
        (ex, ey), angle, speed, lane = (
            ego[tc.VAR_POSITION],
            ego[tc.VAR_ANGLE],
            ego[tc.VAR_SPEED],
            ego[tc.VAR_LANE_ID],
        )
        ego_rows.append((ex, ey, angle, speed))
        if not lanes or lanes[-1] != lane:
            lanes.append(lane)
        around: dict[str, tuple[float, float, float]] = {}
        context = conn.vehicle.getContextSubscriptionResults(EGO) or {}
        for name, values in context.items():
            if name == EGO:
                continue
            x, y = values[tc.VAR_POSITION]
            around[name] = (x, y, values[tc.VAR_ANGLE])
            if name not in sizes:
                sizes[name] = _size(conn, name)
        steps.append(around)
        if replay is not None:
            event = _replay(conn, k, director, replay, event)
            if event is not None and end < 0:
                end = k + director.after
            if event is not None and k >= end:
                break
            continue
        if event is None:
            event = director.step(conn, k)
            if event is not None:
                end = k + director.after
        else:
            director.check(conn, k, event)
            if k >= end:
                break
    assert event is not None
    return _finish(steps, ego_rows, lanes, sizes, first + 1, event, director, net)


def _replay(
    conn: Any, k: int, director: Director, replay: Replay, event: Event | None
) -> Event | None:
    """One step of a replay: the first run's commands of step ``k``, the ego placed where
    our ego is at the next step, and the event (given, or observed again)."""
    try:
        for _, domain, method, args in (a for a in replay.actions if a[0] == k):
            getattr(getattr(conn, domain), method)(*args)
        if k + 1 in replay.track:
            x, y, angle = replay.track[k + 1]
            conn.vehicle.setSpeedMode(EGO, 0)
            conn.vehicle.moveToXY(EGO, "", -1, x, y, angle, 1)
        elif k in replay.track:
            conn.vehicle.setSpeedMode(EGO, 31)
    except Exception as error:  # a TraCI error: a road user of the first run is not there
        raise Refused(f"the replay diverged: {error}") from None
    if event is not None:
        return event
    if replay.detect:
        return director.detect(conn, k)
    return replay.event if k >= replay.event.step else None


def _size(conn: Any, name: str) -> tuple[float, float, str]:
    """Length, width and kind of a road user (asked once)."""
    if name in conn.vehicle.getIDList():
        return conn.vehicle.getLength(name), conn.vehicle.getWidth(name), "vehicle"
    return conn.person.getLength(name), conn.person.getWidth(name), "pedestrian"


def _finish(
    steps: list[dict[str, tuple[float, float, float]]],
    ego_rows: list[tuple[float, float, float, float]],
    lanes: list[str],
    sizes: dict[str, tuple[float, float, str]],
    first_step: int,
    event: Event,
    director: Director,
    net: Path,
) -> Recording:
    ids = sorted(sizes)
    index = {name: n for n, name in enumerate(ids)}
    front = np.full((len(steps), len(ids), 2), np.nan)
    angle = np.full((len(steps), len(ids)), np.nan)
    for r, around in enumerate(steps):
        for name, (x, y, a) in around.items():
            front[r, index[name]] = (x, y)
            angle[r, index[name]] = a
    ego = np.asarray(ego_rows, dtype=np.float64)
    return Recording(
        first_step=first_step,
        ids=ids,
        kinds=[sizes[i][2] for i in ids],
        size=np.array([sizes[i][:2] for i in ids], dtype=np.float64).reshape(-1, 2),
        front=front,
        angle=angle,
        ego_xy=ego[:, :2],
        ego_angle=ego[:, 2],
        ego_speed=ego[:, 3],
        ego_lanes=lanes,
        ego_route=director.ego_route,
        event=event,
        net=net,
    )


def heading(angle_deg: float) -> float:
    """SUMO's angle (deg clockwise from north) as a heading (rad, counter-clockwise from
    east) in SUMO's frame."""
    return math.radians(90.0 - angle_deg)
