"""A test stack: publishes a run over DDS the way a driving stack does.

``python test/stack_publisher.py --synth cut_in:perception:1 --layout carla ...`` (the venv's
python, a separate process). A stack publishes no frame markers, no run metadata and no
player status: each topic carries its own header stamps (here the log stamp plus a fixed
per-topic offset; the ego odometry, the reference, is not offset), messages arrive jittered
(each sent a random delay after its frame's send time, so topics and, with a jitter above
the period, frames reorder), ``/clock`` carries the frame stamp, and the collision is
announced on a topic after the collision frame's data with the document the monitors read
(``ads_rca.live.results.collision_frame``). Layouts: ``contract`` (our codecs on the
contract topics under ``--namespace``) and ``carla`` (what a CARLA ROS bridge stack sends:
odometry, the bridge's CUBE markers, a ``nav_msgs/Path`` plan, our MarkerArrays for the
rest on stack-like names, see :data:`CARLA_TOPICS`). Messages come from the existing
builders (the codecs of the topic table, :mod:`ads_rca.contract.stack_inputs`).

The pure part (:func:`parse_args`, :func:`load_run`, :func:`make_schedule`) imports no rclpy,
so the tests compute what must arrive from it; :func:`publish` is the DDS shell. Bad
options are one line and exit status 2; at the end the offsets, the counts sent and the
dropped log stamps are printed as one JSON line on stdout.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from ads_rca.contract import live_topics, topics
from ads_rca.contract.convert import clock_message, string_message
from ads_rca.contract.jsontext import dumps_json
from ads_rca.contract.stack_inputs import actors_to_carla_markers, plan_to_path
from ads_rca.errors import AdsRcaError
from ads_rca.model import FOLDERS, RunLog

LAYOUTS = ("contract", "carla")
#: The folder whose header stamps define the frames (never offset).
REFERENCE = "pose"
#: The carla layout's topic of every folder (a CARLA ROS bridge stack's names; the 2D boxes
#: and predictions are our contract MarkerArrays on names such a stack might use).
CARLA_TOPICS: dict[str, str] = {
    "pose": "/carla/ego_vehicle/odometry",
    "actors": "/carla/markers",
    "bboxes": "/perception/detections_2d",
    "bboxes_gt": "/perception/ground_truth_2d",
    "predictions": "/prediction/objects",
    "predictions_with_perception": "/prediction/objects_with_perception",
    "waypoint": "/planning/path",
}
MARKER_ARRAY = "visualization_msgs/msg/MarkerArray"
STRING = "std_msgs/msg/String"
CLOCK_TYPE = topics.MESSAGE_TYPE_NAMES[topics.CLOCK]
#: At rate 0: messages sent between waits for every acknowledgement (below the depth 100).
ACK_EVERY = 50
WAIT_TIMEOUT_S = 10.0
#: Independent random streams (one per purpose) drawn from ``--seed``.
_OFFSETS, _JITTER, _DROPS = 1, 2, 3

# record, header stamp (ms), timesteps per frame -> message object
Builder = Callable[[Any, int, int], Any]


class StackError(AdsRcaError):
    """An option or input the test stack cannot use (one line, exit status 2)."""


@dataclass(frozen=True)
class Settings:
    """The command line, checked."""

    synth: tuple[str, str, int] | None
    log: Path | None
    layout: str = "contract"
    namespace: str = topics.DEFAULT_NAMESPACE
    offset_ms: int = 20
    jitter_ms: float = 30.0
    drops: tuple[tuple[str, float], ...] = ()
    rate: float = 0.0
    seed: int = 0
    collision_topic: str = ""
    wait_subscribers: int = 1
    #: Subscribers the collision topic must have before publishing starts (the monitors
    #: and the aggregator: an aggregator matched after the publisher left never hears the
    #: latched collision, and waits for it forever); 0: as many as the data topics.
    #: Given, it is the count there whatever the data topics' (a companion node, such as
    #: a predictor, listens to the data topics only).
    wait_collision_subscribers: int = 0

    @property
    def collision_name(self) -> str:
        return self.collision_topic or topics.topic_name(live_topics.COLLISION, self.namespace)


@dataclass(frozen=True)
class Outgoing:
    """One message to send: at ``due_ms`` of log time after the first frame (rate 1)."""

    due_ms: float
    topic: str
    type_name: str
    message: Any
    folder: str | None  # the log folder of a data message; None: /clock, collision
    log_stamp_ms: int
    header_stamp_ms: int


@dataclass(frozen=True)
class Schedule:
    """What the stack sends, in sending order, and what it left out."""

    messages: tuple[Outgoing, ...]
    #: Full topic name -> message type name, every topic published (collision included).
    topic_types: dict[str, str]
    #: Folder -> its topic's fixed header stamp offset (ms).
    offsets_ms: dict[str, int]
    #: Folder -> log stamps of its records not sent.
    dropped: dict[str, list[int]]
    #: Folder -> full topic name.
    folder_topics: dict[str, str]

    def summary(self) -> dict[str, Any]:
        """The JSON line printed at the end."""
        sent: dict[str, int] = {}
        for out in self.messages:
            sent[out.topic] = sent.get(out.topic, 0) + 1
        return {"offsets_ms": self.offsets_ms, "dropped": self.dropped, "sent": sent}


# --- the command line -------------------------------------------------------------------------


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:  # one line, not argparse's usage block
        self.exit(2, f"stack_publisher: {message}\n")


def _synth_spec(text: str) -> tuple[str, str, int]:
    from ads_rca.synth import FAULTS, SCENARIOS

    parts = text.split(":")
    if len(parts) != 3:
        raise StackError(f"--synth {text!r}: expected SCENARIO:FAULT:SEED")
    scenario, fault, seed = parts
    if scenario not in SCENARIOS:
        raise StackError(f"--synth {text!r}: scenario must be one of {', '.join(SCENARIOS)}")
    if fault not in FAULTS:
        raise StackError(f"--synth {text!r}: fault must be one of {', '.join(FAULTS)}")
    try:
        return scenario, fault, int(seed)
    except ValueError:
        raise StackError(f"--synth {text!r}: seed {seed!r} is not an integer") from None


def _drop_spec(text: str) -> tuple[str, float]:
    folder, _, fraction = text.partition(":")
    if folder not in FOLDERS:
        raise StackError(f"--drop {text!r}: folder must be one of {', '.join(FOLDERS)}")
    try:
        value = float(fraction)
    except ValueError:
        value = float("nan")
    if not 0.0 <= value <= 1.0:
        raise StackError(f"--drop {text!r}: fraction {fraction!r} is not a number in [0, 1]")
    return folder, value


def _at_least(low: float, what: str) -> Callable[[str], float]:
    def check(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = float("nan")
        if not value >= low:
            raise argparse.ArgumentTypeError(f"{what} must be a number >= {low}, not {text!r}")
        return value

    return check


def parse_args(argv: Sequence[str]) -> Settings:
    """The checked settings; StackError (or argparse's one-line exit 2) for a bad option."""
    parser = _Parser(prog="stack_publisher", description=__doc__)
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--synth", metavar="SCENARIO:FAULT:SEED")
    source.add_argument("--log", metavar="DIR")
    parser.add_argument("--layout", choices=LAYOUTS, default="contract")
    parser.add_argument("--namespace", default=topics.DEFAULT_NAMESPACE)
    parser.add_argument("--offset-ms", type=int, default=20)
    parser.add_argument("--jitter-ms", type=_at_least(0.0, "--jitter-ms"), default=30.0)
    parser.add_argument("--drop", action="append", default=[], metavar="FOLDER:FRACTION")
    parser.add_argument("--rate", type=_at_least(0.0, "--rate"), default=0.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--collision-topic", default="")
    parser.add_argument("--wait-subscribers", type=int, default=1)
    parser.add_argument("--wait-collision-subscribers", type=int, default=0)
    args = parser.parse_args(list(argv))
    if args.offset_ms < 0:
        raise StackError(f"--offset-ms must be >= 0, not {args.offset_ms}")
    for flag, count in (
        ("--wait-subscribers", args.wait_subscribers),
        ("--wait-collision-subscribers", args.wait_collision_subscribers),
    ):
        if count < 0:
            raise StackError(f"{flag} must be >= 0, not {count}")
    drops = tuple(_drop_spec(text) for text in args.drop)
    if len({folder for folder, _ in drops}) != len(drops):
        raise StackError("--drop names a folder twice")
    log = None
    if args.log is not None:
        log = Path(args.log)
        if not log.exists():
            raise StackError(f"--log {args.log}: no such log folder")
    return Settings(
        synth=_synth_spec(args.synth) if args.synth is not None else None,
        log=log,
        layout=args.layout,
        namespace=args.namespace,
        offset_ms=args.offset_ms,
        jitter_ms=args.jitter_ms,
        drops=drops,
        rate=args.rate,
        seed=args.seed,
        collision_topic=args.collision_topic,
        wait_subscribers=args.wait_subscribers,
        wait_collision_subscribers=args.wait_collision_subscribers,
    )


def load_run(settings: Settings) -> RunLog:
    """The synthesised run or the log folder (ads_rca's own errors are one line)."""
    if settings.synth is not None:
        from ads_rca.synth import synthesise

        return synthesise(*settings.synth)
    from ads_rca.sources.registry import open_run

    assert settings.log is not None
    return open_run(settings.log)


# --- the schedule (pure) --------------------------------------------------------------------


def _rng(seed: int, purpose: int) -> np.random.Generator:
    return np.random.default_rng([seed, purpose])


def topic_offsets(seed: int, max_ms: int) -> dict[str, int]:
    """Folder -> its fixed header stamp offset in [-max_ms, max_ms]; the reference gets 0."""
    rng = _rng(seed, _OFFSETS)
    drawn = {folder: int(rng.integers(-max_ms, max_ms + 1)) for folder in FOLDERS}
    return drawn | {REFERENCE: 0}


def dropped_stamps(
    log: RunLog, drops: Sequence[tuple[str, float]], seed: int
) -> dict[str, list[int]]:
    """Folder -> the log stamps not sent: round(fraction × records), drawn from the seed."""
    rng = _rng(seed, _DROPS)
    out: dict[str, list[int]] = {}
    for folder, fraction in drops:
        stamps = sorted(log.folder(folder))
        count = round(fraction * len(stamps))
        out[folder] = sorted(int(s) for s in rng.choice(stamps, size=count, replace=False))
    return out


def _builders(settings: Settings) -> dict[str, tuple[str, str, Builder]]:
    """Folder -> (full topic name, message type name, builder) of the layout."""
    out: dict[str, tuple[str, str, Builder]] = {}
    for folder in FOLDERS:
        row = topics.TOPICS[topics.FOLDER_TOPICS[folder]]
        name = topics.topic_name(row.key, settings.namespace)
        out[folder] = (name, row.codec.type_name, row.codec.build)
    if settings.layout == "carla":
        for folder, (_, type_name, build) in out.items():
            out[folder] = (CARLA_TOPICS[folder], type_name, build)
        out["actors"] = (
            CARLA_TOPICS["actors"],
            MARKER_ARRAY,
            lambda actors, stamp, frame_ms: actors_to_carla_markers(actors, stamp),
        )
        out["waypoint"] = (CARLA_TOPICS["waypoint"], "nav_msgs/msg/Path", plan_to_path)
    return out


def make_schedule(log: RunLog, settings: Settings) -> Schedule:
    """Every message of the run in sending order (by due time; /clock first in its frame,
    the collision document after the collision frame's data)."""
    builders = _builders(settings)
    offsets = topic_offsets(settings.seed, settings.offset_ms)
    dropped = dropped_stamps(log, settings.drops, settings.seed)
    jitter = _rng(settings.seed, _JITTER)
    frames = log.unique_frames
    first = frames[0] if frames else 0
    # (due, rank, order): the clock (rank 0) before a frame's data (rank 1) at equal due.
    keyed: list[tuple[float, int, int, Outgoing]] = []
    for stamp in frames:
        send_ms = float(stamp - first)
        clock = clock_message(stamp)
        keyed.append(
            (
                send_ms,
                0,
                len(keyed),
                Outgoing(send_ms, topics.CLOCK, CLOCK_TYPE, clock, None, stamp, stamp),
            )
        )
        for folder in FOLDERS:
            record = log.folder(folder).get(stamp)
            delay = float(jitter.uniform(0.0, settings.jitter_ms))
            if record is None or stamp in dropped.get(folder, ()):
                continue
            name, type_name, build = builders[folder]
            header_ms = stamp + offsets[folder]
            try:
                message = build(record, header_ms, log.frame_ms)
            except ValueError as error:  # e.g. a CARLA marker id that is not an integer
                raise StackError(f"{folder} at {stamp} ms: {error}") from None
            out = Outgoing(send_ms + delay, name, type_name, message, folder, stamp, header_ms)
            keyed.append((out.due_ms, 1, len(keyed), out))
    collision = log.metadata.collision_frame
    if collision >= 0 and frames:
        collision_ms = collision * log.frame_ms
        before = [k[0] for k in keyed if k[3].log_stamp_ms <= collision_ms]
        due = max([float(collision_ms - first), *before])
        document = dumps_json({"frame": collision, "stamp_ms": collision_ms})
        out = Outgoing(
            due,
            settings.collision_name,
            STRING,
            string_message(document),
            None,
            collision_ms,
            collision_ms,
        )
        keyed.append((due, 2, len(keyed), out))
    keyed.sort(key=lambda k: k[:3])
    types = {out.topic: out.type_name for *_, out in keyed}
    types |= {name: type_name for name, type_name, _ in builders.values()}
    types[settings.collision_name] = STRING
    types[topics.CLOCK] = CLOCK_TYPE
    return Schedule(
        messages=tuple(k[3] for k in keyed),
        topic_types=types,
        offsets_ms=offsets,
        dropped=dropped,
        folder_topics={folder: name for folder, (name, _, _) in builders.items()},
    )


# --- the DDS shell ----------------------------------------------------------------------------


def _message_class(type_name: str) -> type[Any]:
    import importlib

    package, _, name = type_name.split("/")
    cls: type[Any] = getattr(importlib.import_module(f"{package}.msg"), name)
    return cls


def publish(schedule: Schedule, settings: Settings) -> int:
    """Publish the schedule (after every expected subscriber matched); exit status."""
    from rclpy.logging import get_logger
    from rclpy.node import Node
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from ads_rca.ros.nodemain import keep_running, wait_for_acks

    logger = get_logger("stack_publisher")
    node = Node("stack_publisher")
    try:
        stack_qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        pubs = {
            name: node.create_publisher(
                _message_class(type_name),
                name,
                # The monitors read the collision latched (a late joiner still gets it).
                live_topics.latched_qos() if name == settings.collision_name else stack_qos,
            )
            for name, type_name in schedule.topic_types.items()
        }
        # Topics the run has messages for (a scene without boxes declares their topics, but
        # no monitor need listen there).
        carrying = {out.topic for out in schedule.messages}
        needed = {
            name: settings.wait_subscribers
            for name in pubs
            if name != topics.CLOCK and name in carrying
        }
        needed[settings.collision_name] = (
            settings.wait_collision_subscribers or settings.wait_subscribers
        )
        if not _wait_for_subscribers(pubs, needed, settings.wait_subscribers):
            counts = {name: (pubs[name].get_subscription_count(), n) for name, n in needed.items()}
            short = {name: got_n for name, got_n in counts.items() if got_n[0] < got_n[1]}
            shown = short or counts  # stopped (Ctrl-C) with every topic served: say them all
            logger.error(
                f"only {min(got for got, _ in shown.values())} of "
                f"{max(n for _, n in shown.values())} subscribers after "
                f"{WAIT_TIMEOUT_S} s on {', '.join(sorted(short))}"
            )
            return 1
        start = time.monotonic()
        since_ack = 0
        for out in schedule.messages:
            if not keep_running():
                return 0
            if out.topic == settings.collision_name:  # after the data, whatever DDS does
                wait_for_acks(pubs.values(), WAIT_TIMEOUT_S)
            if settings.rate > 0:
                delay = start + out.due_ms / 1000.0 / settings.rate - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
            elif since_ack >= ACK_EVERY:
                wait_for_acks(pubs.values(), WAIT_TIMEOUT_S)
                since_ack = 0
            pubs[out.topic].publish(out.message)
            since_ack += 1
        if not wait_for_acks(pubs.values(), WAIT_TIMEOUT_S):
            logger.warning("not every message was acknowledged before exit")
        print(json.dumps(schedule.summary(), sort_keys=True), flush=True)
        return 0
    finally:
        node.destroy_node()


def _wait_for_subscribers(pubs: dict[str, Any], needed: dict[str, int], clock: int) -> bool:
    """Every data and collision topic has its ``needed`` subscribers within the timeout;
    then /clock gets a short grace for ``clock`` (nobody need listen to a stack's clock)."""
    from ads_rca.ros.nodemain import keep_running

    deadline = time.monotonic() + WAIT_TIMEOUT_S
    while any(pubs[name].get_subscription_count() < count for name, count in needed.items()):
        if time.monotonic() > deadline or not keep_running():
            return False
        time.sleep(0.01)
    grace = min(deadline, time.monotonic() + 2.0)
    clock_pub = pubs[topics.CLOCK]
    while clock_pub.get_subscription_count() < clock and time.monotonic() < grace:
        time.sleep(0.01)
    return True


def main(argv: Sequence[str]) -> int:
    from ads_rca.foundation.text import printable

    try:
        settings = parse_args(argv)
        schedule = make_schedule(load_run(settings), settings)
    except AdsRcaError as error:
        print(printable(f"stack_publisher: {error}"), file=sys.stderr)
        return 2
    import rclpy
    from rclpy.executors import ExternalShutdownException

    from ads_rca.ros.nodemain import ignore_stop_signals, start_process

    if not start_process("stack_publisher", []):
        return 2
    try:
        return publish(schedule, settings)
    except (KeyboardInterrupt, ExternalShutdownException):
        return 0
    finally:
        rclpy.try_shutdown()
        ignore_stop_signals()


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
