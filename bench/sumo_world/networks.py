"""Road networks built by SUMO's ``netconvert`` from plain node/edge XML written here.

Nothing is downloaded: each family's network is a handful of nodes and edges (curves as
edge shapes, every lane's geometry, junction shapes and the internal lanes' turning arcs are
``netconvert``'s), cached under ``~/.cache/ads_rca/sumo-nets/<hash>`` by the XML's hash.
Coordinates are SUMO's (x east, y north, right-hand traffic); :mod:`sumo_world.scene`
converts them to the log's CARLA frame.

- ``curve``: a three-lane road bending left or right on an arc of radius 80…200 m, two
  lanes the other way;
- ``merge``: a two-lane road with an on-ramp joining through an acceleration lane that ends;
- ``intersection``: a four-way priority junction of two-lane roads (west-east has priority);
- ``dense``: a four-lane road with three lanes the other way and a gentle bend;
- ``crossing``: a two-lane road each way with sidewalks and a zebra crossing (pedestrians
  have priority).
"""

from __future__ import annotations

import hashlib
import math
import subprocess
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from sumo_world.env import CACHE, Sumo

NETS = CACHE / "sumo-nets"


@dataclass
class Network:
    """A network's plain XML (``netconvert`` turns it into a ``.net.xml``)."""

    nodes: list[str] = field(default_factory=list)
    edges: list[str] = field(default_factory=list)
    connections: list[str] = field(default_factory=list)
    options: tuple[str, ...] = ()

    def node(self, name: str, x: float, y: float, kind: str = "priority") -> None:
        self.nodes.append(f'<node id="{name}" x="{x:.2f}" y="{y:.2f}" type="{kind}"/>')

    def edge(
        self,
        name: str,
        start: str,
        end: str,
        lanes: int,
        speed: float,
        shape: Sequence[tuple[float, float]] = (),
        priority: int = 1,
        sidewalk: float = 0.0,
    ) -> None:
        extra = ""
        if shape:
            extra += ' shape="' + " ".join(f"{x:.2f},{y:.2f}" for x, y in shape) + '"'
        if sidewalk:
            extra += f' sidewalkWidth="{sidewalk:.1f}"'
        self.edges.append(
            f'<edge id="{name}" from="{start}" to="{end}" numLanes="{lanes}" '
            f'speed="{speed:.2f}" priority="{priority}"{extra}/>'
        )

    def xml(self) -> dict[str, str]:
        files = {
            "net.nod.xml": "<nodes>\n" + "\n".join(self.nodes) + "\n</nodes>\n",
            "net.edg.xml": "<edges>\n" + "\n".join(self.edges) + "\n</edges>\n",
        }
        if self.connections:
            body = "\n".join(self.connections)
            files["net.con.xml"] = f"<connections>\n{body}\n</connections>\n"
        return files

    def build(self, sumo: Sumo) -> Path:
        """The ``.net.xml`` (built by ``netconvert`` unless cached)."""
        files = self.xml()
        digest = hashlib.sha256(
            repr((sorted(files.items()), self.options, sumo.version)).encode()
        ).hexdigest()[:16]
        folder = NETS / digest
        net = folder / "net.net.xml"
        if net.exists():
            return net
        folder.mkdir(parents=True, exist_ok=True)
        for name, text in files.items():
            (folder / name).write_text(text, encoding="utf-8")
        command = [
            str(sumo.netconvert),
            "--node-files",
            str(folder / "net.nod.xml"),
            "--edge-files",
            str(folder / "net.edg.xml"),
            "--offset.disable-normalization",
            "--no-turnarounds",
            "--junctions.corner-detail",
            "8",
            "--default.lanewidth",
            "3.5",
            "--no-warnings",
            "--output-file",
            str(folder / "tmp.net.xml"),
            *self.options,
        ]
        if "net.con.xml" in files:
            command[1:1] = ["--connection-files", str(folder / "net.con.xml")]
        subprocess.run(command, check=True, env=sumo.environment(), capture_output=True)
        (folder / "tmp.net.xml").rename(net)
        return net


def arc(
    start: tuple[float, float], heading: float, radius: float, angle: float, step: float = 2.0
) -> list[tuple[float, float]]:
    """Points of a circular arc from ``start`` at ``heading`` (rad, SUMO frame), turning by
    ``angle`` (rad, + left) on ``radius``."""
    n = max(int(abs(angle) * radius / step), 4)
    side = 1.0 if angle > 0 else -1.0
    cx = start[0] - side * radius * math.sin(heading)
    cy = start[1] + side * radius * math.cos(heading)
    points = []
    for k in range(n + 1):
        phi = heading + angle * k / n
        points.append((cx + side * radius * math.sin(phi), cy - side * radius * math.cos(phi)))
    return points


def bent_road(
    lead: float,
    radius: float,
    angle: float,
    tail: float,
    lanes: tuple[int, int],
    speed: float,
    names: tuple[str, str, str],
) -> Network:
    """Straight ``lead`` m, an arc of ``radius`` turning ``angle`` (rad, + left), straight
    ``tail`` m; ``lanes`` in the direction of travel and back; its three edges ``names``
    (each way back is the name with a leading "-")."""
    net = Network()
    points = arc((lead, 0.0), 0.0, radius, angle)
    end = points[-1]
    out = (end[0] + tail * math.cos(angle), end[1] + tail * math.sin(angle))
    net.node("n0", 0.0, 0.0)
    net.node("n1", lead, 0.0)
    net.node("n2", *end)
    net.node("n3", *out)
    ahead, back = lanes
    first, bend, last = names
    net.edge(first, "n0", "n1", ahead, speed)
    net.edge(bend, "n1", "n2", ahead, speed, shape=points)
    net.edge(last, "n2", "n3", ahead, speed)
    net.edge(f"-{last}", "n3", "n2", back, speed)
    net.edge(f"-{bend}", "n2", "n1", back, speed, shape=points[::-1])
    net.edge(f"-{first}", "n1", "n0", back, speed)
    return net


def curve(radius: float, angle: float, speed: float) -> Network:
    """Straight 350 m, an arc of ``radius`` turning ``angle`` (rad, + left), straight 300 m;
    three lanes in the direction of travel, two back."""
    return bent_road(350.0, radius, angle, 300.0, (3, 2), speed, ("in", "curve", "out"))


def merge(accel_length: float, speed: float, ramp_speed: float) -> Network:
    """A two-lane road (400 m) gaining an acceleration lane from an on-ramp on its right for
    ``accel_length`` m, then two lanes for 450 m; two lanes back."""
    net = Network()
    x1, x2 = 400.0, 400.0 + accel_length
    net.node("n0", 0.0, 0.0)
    net.node("n1", x1, 0.0)
    net.node("n2", x2, 0.0)
    net.node("n3", x2 + 450.0, 0.0)
    net.node("r0", x1 - 320.0, -95.0)
    ramp = [(x1 - 320.0 + 320.0 * u, -95.0 * (1.0 - u) ** 2) for u in (k / 40 for k in range(41))]
    net.edge("m1", "n0", "n1", 2, speed, priority=3)
    net.edge("m2", "n1", "n2", 3, speed, priority=3)
    net.edge("m3", "n2", "n3", 2, speed, priority=3)
    net.edge("r1", "r0", "n1", 1, ramp_speed, shape=ramp, priority=1)
    net.edge("-m3", "n3", "n2", 2, speed, priority=3)
    net.edge("-m2", "n2", "n1", 2, speed, priority=3)
    net.edge("-m1", "n1", "n0", 2, speed, priority=3)
    net.connections += [
        '<connection from="m1" to="m2" fromLane="0" toLane="1"/>',
        '<connection from="m1" to="m2" fromLane="1" toLane="2"/>',
        '<connection from="r1" to="m2" fromLane="0" toLane="0"/>',
        '<connection from="m2" to="m3" fromLane="1" toLane="0"/>',
        '<connection from="m2" to="m3" fromLane="2" toLane="1"/>',
        '<delete from="r1" to="-m1"/>',
    ]
    return net


def intersection(speed: float, side_speed: float) -> Network:
    """A four-way priority junction at the origin, arms of 300 m, two lanes each way; the
    west-east road has priority."""
    net = Network()
    net.node("c", 0.0, 0.0)
    arms = {"w": (-300.0, 0.0), "e": (300.0, 0.0), "n": (0.0, 300.0), "s": (0.0, -300.0)}
    for name, (x, y) in arms.items():
        net.node(name, x, y)
        main = name in ("w", "e")
        v, prio = (speed, 3) if main else (side_speed, 1)
        net.edge(f"{name}c", name, "c", 2, v, priority=prio)
        net.edge(f"c{name}", "c", name, 2, v, priority=prio)
    return net


def dense(speed: float, bend: float) -> Network:
    """Four lanes (three back) over 1300 m: straight 500 m, a gentle bend of radius 400 m by
    ``bend`` rad, straight on."""
    return bent_road(500.0, 400.0, bend, 600.0, (4, 3), speed, ("a", "b", "c"))


def crossing(speed: float) -> Network:
    """Three lanes each way with 2.5 m sidewalks, 400 m to a zebra crossing at the origin
    (pedestrians have priority) and 400 m on."""
    net = Network(options=("--crossings.guess", "false", "--walkingareas"))
    net.node("w", -400.0, 0.0)
    net.node("c", 0.0, 0.0)
    net.node("e", 400.0, 0.0)
    for start, end in (("w", "c"), ("c", "e"), ("e", "c"), ("c", "w")):
        net.edge(start + end, start, end, 3, speed, sidewalk=2.5)
    net.connections.append('<crossing node="c" edges="wc cw" priority="true" width="4"/>')
    return net
