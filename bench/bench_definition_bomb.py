"""What a hostile message definition costs a diagnosis, next to the honest bag; print a table.

    python bench/bench_definition_bomb.py [--storage mcap|sqlite3] [--timeout 120]

Synthesises a run (``cut_in``, perception fault), writes it as a CARLA ROS bridge + Autoware
stack records it (``write_recording``), and copies that bag with one change: the stored
definition of ``nav_msgs/msg/Odometry`` (the ego's odometry, which the ``carla-autoware``
profile reads) replaced by the field bomb of issue 41, one 1 MB text of 88,123 ``int8``
fields (just under the 1 MiB a definition may have). Then runs ``ads-rca inspect --profile
carla-autoware`` and ``ads-rca diagnose --profile carla-autoware`` on each, each a child
process: its exit status, wall and CPU time, and peak resident set (``os.wait4``). A child
still running after ``--timeout`` seconds is stopped and said. The bags are written by a
child process too: a child's peak counts the memory of the process it was forked from, so
the measuring process stays small.

To measure the code before a change, run it with the old package first on the path
(``PYTHONPATH=/path/to/old/checkout``): the children inherit it.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from timing import ChildRun, run_child

BOMB_TYPE = "nav_msgs/msg/Odometry"
#: The field bomb: 1,046,366 bytes, 88,123 fields.
FIELD_BOMB = "".join(f"int8 f{i}\n" for i in range(88_123))
COMMANDS = ("inspect", "diagnose")


def with_definition(source: Path, target: Path, storage: str, msg_type: str, text: str) -> Path:
    """A copy of the bag ``source`` at ``target`` (``storage``: mcap or sqlite3) whose
    stored definition of ``msg_type`` is ``text`` (every message, topic and other definition
    as they were)."""
    from rosbags.interfaces import ConnectionExtRosbag2
    from rosbags.rosbag2 import Reader, StoragePlugin, Writer

    with Reader(source) as reader:
        plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
        with Writer(target, version=9, storage_plugin=plugin) as out:
            mapping = {}
            for connection in reader.connections:
                ext = connection.ext
                assert isinstance(ext, ConnectionExtRosbag2)
                mapping[connection.id] = out.add_connection(
                    connection.topic,
                    connection.msgtype,
                    msgdef=text if connection.msgtype == msg_type else connection.msgdef.data,
                    rihs01=connection.digest,
                    serialization_format=ext.serialization_format,
                    offered_qos_profiles=ext.offered_qos_profiles,
                )
            for connection, stamp, data in reader.messages():
                out.write(mapping[connection.id], stamp, data)
    return target


def write_bags(root: Path, storage: str) -> None:
    """The honest bag (``root/honest``) and its copy with the field bomb (``root/bomb``)."""
    from ads_rca.synth import synthesise
    from ads_rca.synth.recording import write_recording

    honest = root / "honest"
    write_recording(synthesise("cut_in", "perception", seed=0), honest, storage=storage)
    with_definition(honest, root / "bomb", storage, BOMB_TYPE, FIELD_BOMB)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap")
    parser.add_argument("--timeout", type=float, default=120)
    parser.add_argument("--write", type=Path, help=argparse.SUPPRESS)  # the bags' writer
    args = parser.parse_args()
    if args.write is not None:
        write_bags(args.write, args.storage)
        return
    with tempfile.TemporaryDirectory() as tmp:
        written = run_child([sys.executable, __file__, "--write", tmp, "--storage", args.storage])
        assert written.returncode == 0, written.stderr
        bags = {"honest": Path(tmp) / "honest", "field bomb": Path(tmp) / "bomb"}
        print(f"storage {args.storage}; bomb: {BOMB_TYPE} defined by {len(FIELD_BOMB)} bytes")
        print(f"{'bag':<11} {'command':<9} {'exit':>4} {'wall s':>7} {'CPU s':>7} {'peak MB':>8}")
        for label, bag in bags.items():
            for command in COMMANDS:
                argv = [sys.executable, "-m", "ads_rca.cli", command, str(bag)]
                done = run_child([*argv, "--profile", "carla-autoware"], timeout_s=args.timeout)
                report(label, command, done)


def report(label: str, command: str, done: ChildRun) -> None:
    status = "stopped" if done.timed_out else str(done.returncode)
    print(
        f"{label:<11} {command:<9} {status:>4} {done.wall_s:7.2f} {done.cpu_s:7.2f} "
        f"{done.max_rss_mb:8.0f}"
    )
    lines = done.stderr.strip().splitlines()
    if done.returncode != 0 and lines:
        print(f"    {lines[-1][:160]}")


if __name__ == "__main__":
    main()
