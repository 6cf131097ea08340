"""An independent test stack: publishes a run as a CARLA ROS bridge stack does, without ads_rca.

``python test/independent_stack.py --log RUN [--log RUN2 ...] [options]`` (the venv's python,
its own process). Written from docs/topics.md and docs/live-graph.md only, and importing
nothing of ads_rca, so a test of the live graph against it does not share the product's
own encoders: it reads a running-log folder (``metadata.json``, ``<folder>/<name>-<ms>.json``)
and builds every message itself, in the layout ``config/stack_carla.yaml`` names:

- ``/carla/ego_vehicle/odometry`` (``nav_msgs/Odometry``, the frames' reference, never offset);
- ``/carla/markers``: the bridge's ADD ``CUBE`` markers, one per actor, id = the CARLA id;
- ``/perception/detections_2d`` and ``/perception/ground_truth_2d``, ``/prediction/objects``
  and ``/prediction/objects_with_perception``: the contract's ``MarkerArray`` (DELETEALL,
  then one ``LINE_STRIP`` per box or track, the id and extras in the marker's JSON text);
- ``/planning/path`` (``nav_msgs/Path``, pose stamps = header stamp + key x frame period);
- ``/clock`` each frame, and ``{ns}/run/collision`` (``{"frame", "stamp_ms"}``, latched)
  once the collision frame's data were acknowledged; ``--collision-topic NAME`` sends it
  there instead, and ``--collision-qos volatile`` with the default QoS (reliable, volatile,
  depth 10: what CARLA's collision sensor offers) instead of latched.

CARLA's left-handed frame goes to REP-103 as the bridge does: (x, -y, z), roll, -pitch, -yaw.
Each input but the odometry is stamped with a fixed offset (``--offset-ms``, from ``--seed``)
and sent up to ``--jitter-ms`` after its frame. What a broken stack does, for the tests:
``--drop-input FOLDER`` never publishes an input, ``--stop-input FOLDER:FRAME`` stops it from
that frame on, ``--frames FIRST:LAST`` publishes only those frames (a stack that stops, or a
restarted one: a new process, a new participant), and several ``--log`` runs are sent one
after the other, each with its own stamps (a simulator that restarts: the stamps go back to
the start for a second episode), ``--episode-gap-s`` apart. At the end one JSON line on
stdout says what was sent. Exit status: 0, 1 (subscribers missing), 2 (bad options).
"""

from __future__ import annotations

import argparse
import json
import math
import random
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NoReturn

#: A CARLA ROS bridge stack's topics per log folder (config/stack_carla.yaml).
TOPICS = {
    "pose": "/carla/ego_vehicle/odometry",
    "actors": "/carla/markers",
    "bboxes": "/perception/detections_2d",
    "bboxes_gt": "/perception/ground_truth_2d",
    "predictions": "/prediction/objects",
    "predictions_with_perception": "/prediction/objects_with_perception",
    "waypoint": "/planning/path",
}
REFERENCE = "pose"
#: Marker namespaces of the contract's MarkerArrays (docs/topics.md).
NAMESPACES = {
    "bboxes": "detections",
    "bboxes_gt": "ground_truth",
    "predictions": "predictions",
    "predictions_with_perception": "predictions_with_perception",
}
#: Marker type and action numbers (visualization_msgs/Marker).
CUBE, LINE_STRIP, ADD, DELETEALL = 1, 4, 0, 3
#: At rate 0: messages sent between waits for every acknowledgement.
ACK_EVERY = 40
WAIT_TIMEOUT_S = 20.0


class Refused(Exception):
    """A bad option or log folder: one line, exit status 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        self.exit(2, f"independent_stack: {message}\n")


@dataclass(frozen=True)
class Options:
    logs: tuple[Path, ...]
    namespace: str
    drops: frozenset[str]
    stops: dict[str, int]
    first_frame: int
    last_frame: int
    offset_ms: int
    jitter_ms: float
    seed: int
    rate: float
    episode_gap_s: float
    wait_subscribers: int
    wait_collision_subscribers: int
    collision_topic: str
    collision_volatile: bool


def parse(argv: Sequence[str]) -> Options:
    parser = _Parser(prog="independent_stack", description=__doc__)
    parser.add_argument("--log", action="append", required=True, metavar="DIR")
    parser.add_argument("--namespace", default="/ads_rca")
    parser.add_argument("--drop-input", action="append", default=[], metavar="FOLDER")
    parser.add_argument("--stop-input", action="append", default=[], metavar="FOLDER:FRAME")
    parser.add_argument("--frames", default=":", metavar="FIRST:LAST")
    parser.add_argument("--offset-ms", type=int, default=20)
    parser.add_argument("--jitter-ms", type=float, default=30.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--rate", type=float, default=0.0)
    parser.add_argument("--episode-gap-s", type=float, default=0.5)
    parser.add_argument("--wait-subscribers", type=int, default=1)
    parser.add_argument("--wait-collision-subscribers", type=int, default=2)
    parser.add_argument("--collision-topic", default="", metavar="NAME")
    parser.add_argument("--collision-qos", choices=("latched", "volatile"), default="latched")
    args = parser.parse_args(list(argv))
    for folder in args.drop_input:
        if folder not in TOPICS or folder == REFERENCE:
            raise Refused(f"--drop-input {folder}: not an input folder but the reference")
    stops: dict[str, int] = {}
    for text in args.stop_input:
        folder, _, frame = text.partition(":")
        if folder not in TOPICS or not frame.isdigit():
            raise Refused(f"--stop-input {text}: expected FOLDER:FRAME")
        stops[folder] = int(frame)
    first, _, last = args.frames.partition(":")
    logs = tuple(Path(p) for p in args.log)
    for log in logs:
        if not (log / "metadata.json").is_file():
            raise Refused(f"--log {log}: no metadata.json")
    if not (args.rate >= 0 and args.jitter_ms >= 0 and args.offset_ms >= 0):
        raise Refused("--rate, --jitter-ms and --offset-ms must not be negative")
    return Options(
        logs=logs,
        namespace=args.namespace.rstrip("/"),
        drops=frozenset(args.drop_input),
        stops=stops,
        first_frame=int(first) if first else 0,
        last_frame=int(last) if last else sys.maxsize,
        offset_ms=args.offset_ms,
        jitter_ms=args.jitter_ms,
        seed=args.seed,
        rate=args.rate,
        episode_gap_s=args.episode_gap_s,
        wait_subscribers=args.wait_subscribers,
        wait_collision_subscribers=args.wait_collision_subscribers,
        collision_topic=args.collision_topic or f"{args.namespace.rstrip('/')}/run/collision",
        collision_volatile=args.collision_qos == "volatile",
    )


# --- the log folder ---------------------------------------------------------------------------


@dataclass
class Run:
    """A running-log folder as read here: per folder, its records by stamp (ms)."""

    frame_ms: int
    collision_frame: int
    records: dict[str, dict[int, Any]] = field(default_factory=dict)

    @property
    def stamps(self) -> list[int]:
        return sorted({s for by_stamp in self.records.values() for s in by_stamp})


def read_run(folder: Path) -> Run:
    metadata = json.loads((folder / "metadata.json").read_text())
    run = Run(int(metadata["timesteps_per_frame"]), int(metadata.get("collision_frame", -1)))
    for name in TOPICS:
        by_stamp: dict[int, Any] = {}
        for path in sorted((folder / name).glob("*.json")) if (folder / name).is_dir() else ():
            stamp = int(path.stem.rsplit("-", 1)[1])
            by_stamp[stamp] = json.loads(path.read_text())
        run.records[name] = by_stamp
    return run


# --- the messages -----------------------------------------------------------------------------


def stamp_of(ms: int) -> Any:
    from builtin_interfaces.msg import Time

    return Time(sec=ms // 1000, nanosec=(ms % 1000) * 1_000_000)


def header(ms: int, frame_id: str) -> Any:
    from std_msgs.msg import Header

    return Header(stamp=stamp_of(ms), frame_id=frame_id)


def quaternion(roll_deg: float, pitch_deg: float, yaw_deg: float) -> Any:
    """CARLA's rotation in REP-103 (roll, -pitch, -yaw; static x-y-z Euler angles)."""
    from geometry_msgs.msg import Quaternion

    r, p, y = (math.radians(a) / 2 for a in (roll_deg, -pitch_deg, -yaw_deg))
    cr, cp, cy = math.cos(r), math.cos(p), math.cos(y)
    sr, sp, sy = math.sin(r), math.sin(p), math.sin(y)
    return Quaternion(
        x=sr * cp * cy - cr * sp * sy,
        y=cr * sp * cy + sr * cp * sy,
        z=cr * cp * sy - sr * sp * cy,
        w=cr * cp * cy + sr * sp * sy,
    )


def point(x: float, y: float, z: float) -> Any:
    from geometry_msgs.msg import Point

    return Point(x=float(x), y=float(y), z=float(z))


def odometry(pose: dict[str, Any], ms: int, _frame_ms: int) -> Any:
    from nav_msgs.msg import Odometry

    value = {k: float(v) for k, v in pose.items() if k != "timestamp"}
    msg = Odometry(header=header(ms, "map"), child_frame_id="base_link")
    msg.pose.pose.position = point(value["x"], -value["y"], value["z"])
    msg.pose.pose.orientation = quaternion(value["roll"], value["pitch"], value["yaw"])
    msg.twist.twist.linear.x = value["speed"]
    return msg


def carla_markers(actors: dict[str, Any], ms: int, _frame_ms: int) -> Any:
    from geometry_msgs.msg import Vector3
    from visualization_msgs.msg import Marker, MarkerArray

    markers = []
    for actor_id, actor in actors.items():
        loc, rot, ext = actor["location"], actor["rotation"], actor["extent"]
        marker = Marker(header=header(ms, "map"), id=int(actor_id), type=CUBE, action=ADD)
        marker.pose.position = point(loc["x"], -loc["y"], loc["z"])
        marker.pose.orientation = quaternion(rot["roll"], rot["pitch"], rot["yaw"])
        marker.scale = Vector3(x=2.0 * ext["x"], y=2.0 * ext["y"], z=2.0 * ext["z"])
        marker.color.a = marker.color.g = 1.0
        markers.append(marker)
    return MarkerArray(markers=markers)


def _line_strips(ns: str, frame_id: str, ms: int, strips: list[tuple[list[Any], str]]) -> Any:
    """DELETEALL, then one ADD LINE_STRIP per (points, text) (docs/topics.md)."""
    from visualization_msgs.msg import Marker, MarkerArray

    markers = [Marker(header=header(ms, frame_id), ns=ns, action=DELETEALL)]
    for index, (points, text) in enumerate(strips):
        marker = Marker(header=header(ms, frame_id), ns=ns, id=index, type=LINE_STRIP)
        marker.action, marker.points, marker.text = ADD, points, text
        marker.pose.orientation.w = 1.0
        marker.scale.x, marker.color.a, marker.color.r = 0.2, 1.0, 1.0
        markers.append(marker)
    return MarkerArray(markers=markers)


def boxes(folder: str) -> Any:
    def build(items: list[dict[str, Any]], ms: int, _frame_ms: int) -> Any:
        strips = []
        for box in items:
            (x1, y1), (x2, y2) = box["bounding_box"]
            corners = [point(x1, y1, 0), point(x2, y1, 0), point(x2, y2, 0), point(x1, y2, 0)]
            extras = {k: v for k, v in box.items() if k not in ("id", "bounding_box")}
            text = json.dumps({"id": str(box["id"]), **extras})
            strips.append(([*corners, corners[0]], text))
        return _line_strips(NAMESPACES[folder], "camera_image", ms, strips)

    return build


def tracks(folder: str) -> Any:
    def build(obstacles: dict[str, Any], ms: int, _frame_ms: int) -> Any:
        strips = []
        for obstacle_id, steps in obstacles.items():
            points = [point(s["x"], -s["y"], s["z"]) for s in steps.values()]
            strips.append((points, json.dumps({"id": obstacle_id, "keys": list(steps)})))
        return _line_strips(NAMESPACES[folder], "base_link", ms, strips)

    return build


def path(plan: dict[str, Any], ms: int, frame_ms: int) -> Any:
    from geometry_msgs.msg import PoseStamped
    from nav_msgs.msg import Path as PathMessage

    poses = []
    for key, waypoint in plan.items():
        pose = PoseStamped(header=header(ms + int(key) * frame_ms, "map"))
        pose.pose.position = point(waypoint["x"], -waypoint["y"], 0.0)
        pose.pose.orientation.w = 1.0
        poses.append(pose)
    return PathMessage(header=header(ms, "map"), poses=poses)


BUILDERS: dict[str, tuple[str, Any]] = {
    "pose": ("nav_msgs/msg/Odometry", odometry),
    "actors": ("visualization_msgs/msg/MarkerArray", carla_markers),
    "bboxes": ("visualization_msgs/msg/MarkerArray", boxes("bboxes")),
    "bboxes_gt": ("visualization_msgs/msg/MarkerArray", boxes("bboxes_gt")),
    "predictions": ("visualization_msgs/msg/MarkerArray", tracks("predictions")),
    "predictions_with_perception": (
        "visualization_msgs/msg/MarkerArray",
        tracks("predictions_with_perception"),
    ),
    "waypoint": ("nav_msgs/msg/Path", path),
}


# --- what is sent -------------------------------------------------------------------------------


@dataclass(frozen=True)
class Outgoing:
    due_ms: float
    topic: str
    message: Any
    folder: str | None  # None: /clock or the collision


def offsets(options: Options) -> dict[str, int]:
    rng = random.Random(options.seed)
    drawn = {f: rng.randint(-options.offset_ms, options.offset_ms) for f in TOPICS}
    return drawn | {REFERENCE: 0}


def schedule(run: Run, options: Options, shifts: dict[str, int]) -> list[Outgoing]:
    """One episode's messages in sending order; the collision last, after its frame's data."""
    from rosgraph_msgs.msg import Clock
    from std_msgs.msg import String

    rng = random.Random(options.seed + 1)
    chosen = [
        s for s in run.stamps if options.first_frame <= s // run.frame_ms <= options.last_frame
    ]
    start = chosen[0] if chosen else 0
    out: list[tuple[float, int, int, Outgoing]] = []
    for stamp in chosen:
        frame, due = stamp // run.frame_ms, float(stamp - start)
        out.append((due, 0, len(out), Outgoing(due, "/clock", Clock(clock=stamp_of(stamp)), None)))
        for folder, (_, build) in BUILDERS.items():
            record = run.records[folder].get(stamp)
            late = rng.uniform(0.0, options.jitter_ms)
            if record is None or folder in options.drops:
                continue
            if folder in options.stops and frame >= options.stops[folder]:
                continue
            message = build(record, stamp + shifts[folder], run.frame_ms)
            sending = Outgoing(due + late, TOPICS[folder], message, folder)
            out.append((sending.due_ms, 1, len(out), sending))
    cf = run.collision_frame
    if cf >= 0 and chosen and chosen[0] <= cf * run.frame_ms <= chosen[-1]:
        document = json.dumps({"frame": cf, "stamp_ms": cf * run.frame_ms})
        due = max(o[0] for o in out)
        collision = Outgoing(due, options.collision_topic, String(data=document), None)
        out.append((due, 2, len(out), collision))
    out.sort(key=lambda item: item[:3])
    return [item[3] for item in out]


# --- DDS ----------------------------------------------------------------------------------------


def _message_class(type_name: str) -> Any:
    import importlib

    package, _, name = type_name.split("/")
    return getattr(importlib.import_module(f"{package}.msg"), name)


def publish(options: Options) -> int:
    from rclpy.duration import Duration
    from rclpy.node import Node
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from rosgraph_msgs.msg import Clock
    from std_msgs.msg import String

    runs = [read_run(log) for log in options.logs]
    shifts = offsets(options)
    node = Node("independent_stack")
    data_qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    latched = QoSProfile(
        depth=1,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
    )
    collision_topic = options.collision_topic
    pubs: dict[str, Any] = {
        TOPICS[f]: node.create_publisher(_message_class(t), TOPICS[f], data_qos)
        for f, (t, _) in BUILDERS.items()
        if f not in options.drops
    }
    pubs["/clock"] = node.create_publisher(Clock, "/clock", data_qos)
    collision_qos = QoSProfile(depth=10) if options.collision_volatile else latched
    pubs[collision_topic] = node.create_publisher(String, collision_topic, collision_qos)
    needed = {t: options.wait_subscribers for t in pubs if t not in ("/clock", collision_topic)}
    needed[collision_topic] = options.wait_collision_subscribers

    def acked() -> bool:
        return all(p.wait_for_all_acked(Duration(seconds=WAIT_TIMEOUT_S)) for p in pubs.values())

    try:
        deadline = time.monotonic() + WAIT_TIMEOUT_S
        while any(pubs[t].get_subscription_count() < n for t, n in needed.items()):
            if time.monotonic() > deadline:
                short = sorted(t for t, n in needed.items() if pubs[t].get_subscription_count() < n)
                print(
                    f"independent_stack: too few subscribers on {', '.join(short)}", file=sys.stderr
                )
                return 1
            time.sleep(0.01)
        summary: list[dict[str, Any]] = []
        for number, run in enumerate(runs):
            if number:
                time.sleep(options.episode_gap_s)  # the simulator restarting
            sent: dict[str, int] = {}
            since_ack = 0
            start = time.monotonic()
            for out in schedule(run, options, shifts):
                if out.topic == collision_topic or since_ack >= ACK_EVERY:
                    acked()  # the collision after every data message before it
                    since_ack = 0
                if options.rate > 0:
                    time.sleep(
                        max(0.0, start + out.due_ms / 1000.0 / options.rate - time.monotonic())
                    )
                pubs[out.topic].publish(out.message)
                sent[out.topic] = sent.get(out.topic, 0) + 1
                since_ack += 1
            acked()
            summary.append({"log": str(options.logs[number]), "sent": sent})
        print(json.dumps({"episodes": summary, "offsets_ms": shifts}), flush=True)
        return 0
    finally:
        node.destroy_node()


def main(argv: Sequence[str]) -> int:
    try:
        options = parse(argv)
    except Refused as error:
        print(f"independent_stack: {error}", file=sys.stderr)
        return 2
    import rclpy
    from rclpy.executors import ExternalShutdownException

    rclpy.init()
    try:
        return publish(options)
    except (KeyboardInterrupt, ExternalShutdownException):
        return 0
    finally:
        rclpy.try_shutdown()


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
