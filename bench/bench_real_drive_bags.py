"""Attribution on bags shaped like a real drive, diagnosed through the commands a user runs.

For every scenario × fault × seed: synthesise a crash, write it as a CARLA ROS bridge +
Autoware stack records it, and copy that bag without the ground truth (``/carla/objects``)
and the collision (``/carla/ego_vehicle/collision``), which a real vehicle records neither of.
Then, as a user with a real recording would: ``ads-rca inspect BAG --write-profile P`` (the
starting profile, used unedited), and ``ads-rca diagnose BAG --profile P --event-time T
--json J`` with ``T`` the contact's time in seconds from the stripped recording's first
message (the removed collision message's log time). The verdict's primary root cause (or
"suspected" for "perception suspected") is tallied against the injected fault: prediction,
planning and controller faults must be named; a perception fault is named where the
evidence allows, else suspected; another module named for it is a misattribution.

This is consistency with our own synthesiser (its crash physics and fault models), written
through our own bag writer: it is not correctness on real drives.

Prints the confusion table, accuracy per scenario × fault and overall, and the time per run
(synthesis + bag, inspect, diagnose: wall and CPU each).

Usage: ``python bench/bench_real_drive_bags.py [N] [--first SEED] [--scenarios a,b]
[--faults x,y] [--storage mcap|sqlite3]``.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import shutil
import tempfile
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from accuracy import LABELS, SUSPECTED, fault_names
from timing import Clock, Timing

from ads_rca.cli import main as ads_rca
from ads_rca.synth import SCENARIOS, SynthesisError, canonical_fault, fault_module, synthesise
from ads_rca.synth.recording import write_recording

#: What a real vehicle does not record: the simulator's ground truth and its collision sensor.
REMOVED = ("/carla/objects", "/carla/ego_vehicle/collision")
COLLISION_TOPIC = "/carla/ego_vehicle/collision"
STEPS = ("bag", "inspect", "diagnose")


def strip_bag(source: Path, target: Path, storage: str) -> float:
    """Copy the bag ``source`` to ``target`` without :data:`REMOVED`; return the contact's
    time (s) from the copy's first message: the first collision message's log time."""
    from rosbags.interfaces import ConnectionExtRosbag2
    from rosbags.rosbag2 import Reader, StoragePlugin, Writer

    collision_ns: int | None = None
    first_ns: int | None = None
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Reader(source) as reader:
        kept = [c for c in reader.connections if c.topic not in REMOVED]
        extensions = {c.id: c.ext for c in kept if isinstance(c.ext, ConnectionExtRosbag2)}
        out = Writer(target, version=9, storage_plugin=plugin)
        out.open()
        try:
            mapping = {
                c.id: out.add_connection(
                    c.topic,
                    c.msgtype,
                    typestore=None,
                    msgdef=c.msgdef.data,
                    rihs01=c.digest,
                    serialization_format=extensions[c.id].serialization_format,
                    offered_qos_profiles=extensions[c.id].offered_qos_profiles,
                )
                for c in kept
            }
            for connection, stamp, data in reader.messages():
                if connection.topic == COLLISION_TOPIC and collision_ns is None:
                    collision_ns = stamp
                if connection.id in mapping:
                    first_ns = stamp if first_ns is None else min(first_ns, stamp)
                    out.write(mapping[connection.id], stamp, data)
        finally:
            out.close()
    if collision_ns is None or first_ns is None:
        raise SystemExit(f"{source}: no collision message or no message kept")
    return (collision_ns - first_ns) / 1e9


def quiet(argv: list[str]) -> int:
    """``ads-rca ARGV`` in this process, its output dropped (the JSON is what is read)."""
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        return ads_rca(argv)


@dataclass
class Tally:
    confusion: Counter[tuple[str, str]] = field(default_factory=Counter)
    cells: Counter[tuple[str, str, bool]] = field(default_factory=Counter)
    times: dict[str, list[Timing]] = field(default_factory=lambda: {s: [] for s in STEPS})
    wrong: list[str] = field(default_factory=list)
    #: The explained event's time − the contact's (ms): 0 unless the event was not the one given.
    event_offsets: Counter[int] = field(default_factory=Counter)


def judge(args: argparse.Namespace, scratch: Path, tally: Tally) -> None:
    for scenario in args.scenarios:
        for fault in args.faults:
            for seed in range(args.first, args.first + args.seeds):
                run = scratch / f"{scenario}-{fault.replace(':', '-')}-{seed}"
                with Clock() as clock:
                    try:
                        log = synthesise(scenario, fault, seed)
                    except SynthesisError as error:
                        print(f"skip {scenario} {fault} {seed}: {error}")
                        continue
                    write_recording(log, run / "sim", "carla-autoware", args.storage)
                    contact_s = strip_bag(run / "sim", run / "drive", args.storage)
                tally.times["bag"].append(clock.timing)
                profile, verdict = run / "drive.yaml", run / "verdict.json"
                with Clock() as clock:
                    status = quiet(["inspect", str(run / "drive"), "--write-profile", str(profile)])
                tally.times["inspect"].append(clock.timing)
                if status != 0:
                    raise SystemExit(f"inspect {run / 'drive'}: exit {status}")
                with Clock() as clock:
                    status = quiet(
                        [
                            "diagnose",
                            str(run / "drive"),
                            "--profile",
                            str(profile),
                            "--event-time",
                            f"{contact_s:.3f}",
                            "--json",
                            str(verdict),
                        ]
                    )
                tally.times["diagnose"].append(clock.timing)
                if status not in (0, 1):
                    raise SystemExit(f"diagnose {run / 'drive'}: exit {status}")
                document = json.loads(verdict.read_text(encoding="utf-8"))
                got = document.get("primary_root_cause") or (
                    SUSPECTED if document.get("suspected") else "none"
                )
                injected = canonical_fault(fault)
                want = fault_module(injected)
                if want == "perception" and got == SUSPECTED:
                    want = SUSPECTED
                event = document.get("event") or {}
                tally.event_offsets[round(1000 * (event.get("time_s", -1.0) - contact_s))] += 1
                tally.confusion[injected, got] += 1
                tally.cells[scenario, injected, got == want] += 1
                if got != want:
                    tally.wrong.append(
                        f"{scenario:20s} {fault:19s} seed {seed:3d}: got {got} "
                        f"({document.get('verdict')})"
                    )
                shutil.rmtree(run)


def report(args: argparse.Namespace, tally: Tally) -> None:
    width = max(len(x) for x in LABELS) + 2
    faults = [canonical_fault(f) for f in args.faults]
    print("injected \\ verdict".ljust(22) + "".join(x.rjust(width) for x in LABELS))
    for injected in faults:
        row = "".join(str(tally.confusion[injected, g]).rjust(width) for g in LABELS)
        print(injected.ljust(22) + row)
    print()
    for scenario in args.scenarios:
        for injected in faults:
            ok, bad = tally.cells[scenario, injected, True], tally.cells[scenario, injected, False]
            if ok + bad:
                print(f"{scenario} × {injected}".ljust(46) + f"{ok}/{ok + bad}")
    print()
    for kind in ("perception", "prediction", "planning", "controller"):
        ok = sum(n for (_, f, good), n in tally.cells.items() if good and fault_module(f) == kind)
        all_ = sum(n for (_, f, _good), n in tally.cells.items() if fault_module(f) == kind)
        if all_:
            print(f"{kind:12s} {ok}/{all_} = {100 * ok / all_:.1f} %")
    print(f"explained event − contact (ms): {dict(sorted(tally.event_offsets.items()))}")
    print()
    print(f"{'step':10s} {'runs':>5s} {'wall s/run':>11s} {'CPU s/run':>10s}")
    for step in STEPS:
        times = tally.times[step]
        if times:
            wall = sum(t.wall_s for t in times) / len(times)
            cpu = sum(t.cpu_s for t in times) / len(times)
            print(f"{step:10s} {len(times):5d} {wall:11.2f} {cpu:10.2f}")
    if tally.wrong:
        print("\nmisattributed:")
        print("\n".join(tally.wrong))


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("seeds", nargs="?", type=int, default=5)
    parser.add_argument("--first", type=int, default=0, help="first seed")
    parser.add_argument("--scenarios", default=",".join(s for s in SCENARIOS if s != "cruise"))
    parser.add_argument("--faults", default="perception,prediction,planning,controller,variants")
    parser.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap")
    args = parser.parse_args(argv)
    args.scenarios = [s for s in args.scenarios.split(",") if s]
    args.faults = fault_names(args.faults)
    tally = Tally()
    with tempfile.TemporaryDirectory(prefix="real_drive_bags_") as scratch:
        judge(args, Path(scratch), tally)
    report(args, tally)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
