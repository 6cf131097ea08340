"""A SUMO recording as the synthesiser's :class:`~ads_rca.synth.world.Scene`.

The window: ``frames`` frames (plus the ``PAD`` warm-up rows the ground-truth predictor
needs) around the event, which falls on ``trigger_frame`` (30…50, drawn like the
synthesiser's; fewer, at least 12, when the partner came into the recording later). The
actors: every road user SUMO reported within the recording radius at every row of the
window (at most :data:`MAX_ACTORS`, the nearest to the SUMO ego), with SUMO's lengths and
widths; the SUMO ego itself is left out, since our stack's ego drives in its place. The
ego's path: the centre lines of the lanes SUMO's ego drove, internal junction lanes
included, then on along its route by the network's connections (``sumolib``), resampled
every 0.5 m and smoothed (Gaussian, σ = 1.5 m) so the heading and curvature are continuous
across the polyline's vertices; it starts where the SUMO ego's centre was at frame 1. The
ego starts at the SUMO ego's speed there and wants the highest speed the SUMO ego drove
before the event.

SUMO's frame is right-handed (y north), the log's is CARLA's (y to the right of x): y is
negated and headings with it (a vehicle's SUMO position is its front bumper; its centre is
half a length behind). The whole scene is then turned and shifted by a seeded rigid motion,
as the synthesiser does, so roads are not axis-aligned.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cache
from typing import Any

import numpy as np

from ads_rca.synth.world import (
    CAR_EXTENTS,
    PAD,
    PEDESTRIAN,
    PEDESTRIAN_EXTENT,
    VEHICLE,
    Path,
    Scene,
    transform_points,
)
from sumo_world.geometry import FloatArray
from sumo_world.record import Recording, Refused, heading

MAX_ACTORS = 60
STEP_M = 0.5
SMOOTH_M = 1.5
EXTEND_M = 200.0
MIN_TRIGGER_FRAME = 12
CAR_HALF_HEIGHT = 0.75


@dataclass
class Built:
    """The scene and what it came from (SUMO ids, the SUMO ego's speeds)."""

    scene: Scene
    sumo_ids: tuple[str, ...]
    partner: str
    first: int  # the SUMO step of frame 0
    rotation: float  # the rigid motion from the (flipped) SUMO frame to the scene's
    offset: FloatArray
    line: FloatArray  # the ego's lane centre line, SUMO frame
    info: dict[str, Any] = field(default_factory=dict)

    def to_scene(self, xy: FloatArray) -> FloatArray:
        """A SUMO point in the scene's frame."""
        out: FloatArray = transform_points(xy * np.array([1.0, -1.0]), self.rotation, self.offset)
        return out

    def to_sumo(self, xy: FloatArray, yaw_deg: float) -> tuple[float, float, float]:
        """A scene pose (centre, yaw in degrees) as SUMO's front bumper (x, y, angle)."""
        c, s = math.cos(-self.rotation), math.sin(-self.rotation)
        dx, dy = xy[0] - self.offset[0], xy[1] - self.offset[1]
        x, y = dx * c - dy * s, -(dx * s + dy * c)
        h = -(math.radians(yaw_deg) - self.rotation)
        half = float(self.scene.ego_extent[0])
        x, y = x + half * math.cos(h), y + half * math.sin(h)
        return x, y, (90.0 - math.degrees(h)) % 360.0


@cache
def _net(path: str, sumolib: Any) -> Any:
    return sumolib.net.readNet(path, withInternal=True)


def lane_polyline(rec: Recording, sumolib: Any) -> FloatArray:
    """The centre line (SUMO frame) of the ego's lanes: those it drove, then on along its
    route by the network's connections."""
    net = _net(str(rec.net), sumolib)
    xy = route_polyline(net, rec.ego_lanes, rec.ego_route)
    end = xy[-1] - xy[-2]
    end /= max(float(np.hypot(*end)), 1e-9)
    tail = xy[-1] + np.arange(STEP_M, EXTEND_M, STEP_M)[:, None] * end
    return smooth(resample(np.vstack([xy, tail]), STEP_M), SMOOTH_M / STEP_M)


def route_polyline(net: Any, driven: list[str], route: tuple[str, ...]) -> FloatArray:
    """The centre line of the lanes ``driven`` (ids), then on along ``route`` by the
    network's connections (internal junction lanes included)."""
    lanes = [net.getLane(name) for name in driven]
    lane = lanes[-1]
    edge = lane.getEdge().getID()
    edges = list(route)
    while not edge.startswith(":") and edge in edges and edges.index(edge) + 1 < len(edges):
        following = edges[edges.index(edge) + 1]
        links = [c for c in lane.getOutgoing() if c.getToLane().getEdge().getID() == following]
        if not links:
            break
        link = links[0]
        via = link.getViaLaneID()
        while via:
            internal = net.getLane(via)
            lanes.append(internal)
            nxt = [c for c in internal.getOutgoing() if c.getViaLaneID()]
            via = nxt[0].getViaLaneID() if nxt else ""
        lane = link.getToLane()
        lanes.append(lane)
        edge = following
    points: list[tuple[float, float]] = []
    for each in lanes:
        for x, y in each.getShape():
            if not points or math.hypot(x - points[-1][0], y - points[-1][1]) > 0.05:
                points.append((x, y))
    return np.asarray(points, dtype=np.float64)


def net_of(path: str, sumolib: Any) -> Any:
    """The network read by ``sumolib`` (internal lanes included; cached)."""
    return _net(path, sumolib)


def resample(xy: FloatArray, step: float) -> FloatArray:
    """Points every ``step`` m along the polyline ``xy``."""
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    at = np.arange(0.0, s[-1], step)
    return np.stack([np.interp(at, s, xy[:, 0]), np.interp(at, s, xy[:, 1])], axis=-1)


def smooth(xy: FloatArray, sigma: float) -> FloatArray:
    """Gaussian smoothing along the polyline (``sigma`` in samples), the ends kept."""
    half = int(3 * sigma)
    kernel = np.exp(-0.5 * (np.arange(-half, half + 1) / sigma) ** 2)
    kernel /= kernel.sum()
    padded = np.concatenate([2 * xy[:1] - xy[half:0:-1], xy, 2 * xy[-1:] - xy[-2 : -half - 2 : -1]])
    out = np.stack([np.convolve(padded[:, k], kernel, mode="valid") for k in range(2)], -1)
    return out


def centres(rec: Recording, front: FloatArray, angle: FloatArray, cols: np.ndarray) -> FloatArray:
    """Centres (SUMO frame) of the road users ``cols`` from their front bumpers (people: as
    reported)."""
    h = np.radians(90.0 - angle)
    vehicle = np.array([rec.kinds[k] == "vehicle" for k in cols])
    back = np.where(vehicle, rec.size[cols, 0] / 2, 0.0)
    out: FloatArray = front - np.stack([np.cos(h), np.sin(h)], -1) * back[..., None]
    return out


def build_scene(
    rec: Recording,
    rng: np.random.Generator,
    frames: int,
    name: str,
    sumolib: Any,
    original: Built | None = None,
) -> Built:
    """The scene of ``rec`` (raises :class:`Refused` if the window does not fit). A replay
    keeps its ``original``'s window, path and ego speeds (its ego was placed, not driven)."""
    line = lane_polyline(rec, sumolib) if original is None else original.line
    first = None if original is None else original.first
    partner = rec.ids.index(rec.event.partner)
    event_step = rec.event.step
    seen = np.flatnonzero(np.isfinite(rec.front[:, partner, 0]))
    if seen.size == 0:
        raise Refused("the partner was never near the ego")
    wanted = int(rng.integers(30, 51))
    room = rec.row(event_step) - int(seen[0]) - PAD - 1
    trigger = min(wanted, room, rec.row(event_step) - PAD - 1)
    if first is not None:
        trigger = event_step - first
    if trigger < MIN_TRIGGER_FRAME:
        raise Refused("the partner appeared too late before its event")
    if trigger > frames - 40:
        raise Refused("the event fell outside the window")
    k0 = event_step - trigger  # the step of frame 0
    r0, r1 = rec.row(k0 - PAD), rec.row(k0 + frames)
    if r0 < 0 or r1 >= rec.front.shape[0]:
        raise Refused("the recording does not cover the window")
    front, angle = rec.front[r0 : r1 + 1], rec.angle[r0 : r1 + 1]
    present = np.flatnonzero(np.isfinite(front[..., 0]).all(axis=0))
    if partner not in present:
        raise Refused("the partner left the recording radius within the window")
    centre = centres(rec, front[:, present], angle[:, present], present)
    ego_front = rec.ego_xy[r0 : r1 + 1]
    reach = np.hypot(*(centre - ego_front[:, None, :]).transpose(2, 0, 1)).min(axis=0)
    keep = present[np.argsort(reach)[:MAX_ACTORS]]
    if partner not in keep:
        keep = np.concatenate([keep[:-1], [partner]])
    centre = centres(rec, front[:, keep], angle[:, keep], keep)

    # The ego's path from its centre at frame 1 on.
    row1 = rec.row(k0 + 1)
    h1 = heading(float(rec.ego_angle[row1]))
    ego_centre = rec.ego_xy[row1] - CAR_EXTENTS[0][0] * np.array([math.cos(h1), math.sin(h1)])
    near = int(np.argmin(np.hypot(*(line - ego_centre).T)))
    points = line[near:]

    rotation = float(rng.uniform(-np.pi, np.pi))
    offset = rng.uniform(-300.0, 300.0, size=2)
    flip = np.array([1.0, -1.0])
    path = Path.from_points(transform_points(points * flip, rotation, offset))
    if original is not None:
        path = original.scene.path
    n = keep.size
    order = rng.permutation(n)
    keep = keep[order]
    centre = centre[:, order]
    xy = transform_points(centre * flip, rotation, offset)
    yaw = np.radians(angle[:, keep] - 90.0) + rotation
    kinds = tuple(VEHICLE if rec.kinds[k] == "vehicle" else PEDESTRIAN for k in keep)
    extent = np.array(
        [
            (rec.size[k, 0] / 2, rec.size[k, 1] / 2, CAR_HALF_HEIGHT)
            if rec.kinds[k] == "vehicle"
            else tuple(PEDESTRIAN_EXTENT)
            for k in keep
        ],
        dtype=np.float64,
    )
    ids = rng.choice(np.arange(100, 10000), size=n + 1, replace=False)
    p = int(np.flatnonzero(keep == partner)[0])
    at = xy[PAD + trigger, p]
    nearest = int(np.argmin(np.hypot(*(path.xy - at).T)))
    road = np.array([math.cos(path.yaw[nearest]), math.sin(path.yaw[nearest])])
    speeds = rec.ego_speed[row1 : rec.row(event_step) + 1]
    ego_speed, desired = float(rec.ego_speed[row1]), float(max(speeds.max(), 1.0))
    if original is not None:
        ego_speed, desired = original.scene.ego_speed, original.scene.desired_speed
    scene = Scene(
        name=name,
        frames=frames,
        path=path,
        ego_id=str(ids[0]),
        ego_extent=CAR_EXTENTS[0].copy(),
        ego_speed=ego_speed,
        desired_speed=desired,
        actor_ids=tuple(str(i) for i in ids[1:]),
        kinds=kinds,
        extent=extent,
        xy=xy,
        yaw=yaw,
        partner=p,
        trigger_frame=trigger,
        prediction_fault_model=rec.event.model,
        road_direction=road,
    )
    return Built(
        scene,
        tuple(rec.ids[k] for k in keep),
        rec.event.partner,
        k0,
        rotation,
        offset,
        line,
        {"sumo_event_step": event_step, "actors": n},
    )
