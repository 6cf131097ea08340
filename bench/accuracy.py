"""Attribution accuracy of the `corrected` semantics on synthesised closed-loop logs.

For every scenario × fault over N seeds: synthesise a log, diagnose it with
:func:`ads_rca.diagnosis.engine.diagnose` (corrected mode, exactly what ``ads-rca diagnose`` runs),
and
compare the primary root cause with the module of the injected fault its
``metadata.json["synthesis"]`` label names ("none" expects "no fault found"; a perception
variant such as ``perception:shifted`` expects ``perception``). Prints the confusion table,
the accuracy per scenario × fault, per scenario and overall, the time it took (diagnosis per
frame, and every log of the level synthesised and diagnosed: wall and CPU time each) and the
misattributed cases (scenario, fault, seed).

``--faults`` takes the variants (``perception:shifted``, ``perception:shrunk``,
``perception:velocity``; ``variants`` stands for all three). ``--drop-2d`` removes
``bboxes``, ``bboxes_gt`` and ``predictions_with_perception`` from each log before diagnosing:
what a recording of a stack that perceives in 3-D (carla-autoware) carries, so perception and
prediction are judged from the 3-D objects alone.

``--bag carla-autoware`` goes further: each log is written as a CARLA ROS bridge + Autoware
stack records it (``--storage`` mcap or sqlite3, rosbags' writer) and read back through the
profile with the bag's own types, as ``ads-rca diagnose BAG --profile carla-autoware`` does.

``--noise 1,3,6,10`` runs the same scenario × fault × seed set at each synthesiser noise
level (``ads-rca synth --noise``) and prints each level's tables, its accuracy per fault kind,
then the accuracy of each fault kind against the noise level; a scene the synthesiser refuses
at a level is skipped and counted. With one level (the default 1) the output is as before.

Usage: ``python bench/accuracy.py [N] [--scenarios a,b] [--faults x,y] [--drop-2d]
[--bag PROFILE [--storage S]] [--noise K,K...] [--first SEED] [--actors K] [--horizon H]
[-p NAME=VALUE ...]`` (``--actors`` and ``--horizon`` are passed to the synthesiser, ``-p``
sets a corrected-mode parameter, e.g. ``-p noise_floor_factor=0`` for the rules without
their noise floors).
"""

from __future__ import annotations

import argparse
import atexit
import shutil
import tempfile
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

from timing import Clock, Timing, timed

from ads_rca.diagnosis.engine import diagnose as diagnose_log
from ads_rca.diagnosis.verdict import Attribution
from ads_rca.errors import ConfigError
from ads_rca.model import RunLog
from ads_rca.params import Params, make_params
from ads_rca.sources.bag.profiles.recording import read_recording
from ads_rca.synth import (
    ALL_FAULTS,
    FAULTS,
    SCENARIOS,
    VARIANT_FAULTS,
    SynthesisError,
    canonical_fault,
    fault_module,
    synthesise,
)
from ads_rca.synth.noise import LEVELS
from ads_rca.synth.recording import PROFILES, write_recording

#: Without ground truth, a verdict that finds no failing module suspects perception.
SUSPECTED = "suspected"
#: A fault is named by its module, as the verdict names it.
LABELS = [*FAULTS, SUSPECTED]


def diagnose(log: RunLog, params: Params | None = None) -> tuple[Attribution, Timing, bool]:
    """The corrected attribution of a log (default parameters unless ``params``), the
    diagnosis's wall and CPU time per analysed frame (ms), and whether the verdict, finding
    no failing module, suspects a module it could not judge (a run without ground truth)."""
    found, took = timed(lambda: diagnose_log(log, params or make_params("corrected")))
    frames = max(len(found.frames), 1)
    timing = Timing(took.wall_s * 1000 / frames, took.cpu_s * 1000 / frames)
    suspected = found.attribution.primary_root_cause is None and bool(found.conclusion.suspected)
    return found.attribution, timing, suspected


def drop_2d(log: RunLog) -> RunLog:
    """``log`` without its 2-D perception and ground-truth-history predictions (in place)."""
    log.bboxes = {}
    log.bboxes_gt = {}
    log.predictions_with_perception = {}
    return log


def through_bag(log: RunLog, profile: str, storage: str, folder: Path) -> RunLog:
    """``log`` written as a ``profile`` stack's recording and read back through the profile."""
    bag = folder / "bag"
    shutil.rmtree(bag, ignore_errors=True)
    write_recording(log, bag, profile, storage)
    return read_recording(bag, profile)


def without_truth(log: RunLog) -> tuple[RunLog, float]:
    """``log`` as a real drive records it: no ground-truth actors, 2-D boxes or predictions
    on ground truth, no collision source; and the contact's time (s) to give as
    ``event_time_s``. The stack's tracks stand in for the world when it is diagnosed."""
    drop_2d(log)
    contact_s = log.metadata.collision_frame * log.frame_ms / 1000.0
    log.actors = {}
    log.frames = tuple(sorted(log.tracks_3d))
    log.metadata = replace(log.metadata, collision_frame=-1, collision_known=False)
    return log, contact_s


def corrected_params(items: Sequence[str]) -> Params:
    """The corrected mode's parameters with ``-p NAME=VALUE`` overrides (checked)."""
    overrides: dict[str, str] = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep:
            raise SystemExit(f"-p: {item!r} is not NAME=VALUE")
        overrides[name.strip()] = value.strip()
    try:
        return make_params("corrected", overrides)
    except ConfigError as error:
        raise SystemExit(f"-p: {error}") from None


def fault_names(text: str) -> list[str]:
    """The faults ``--faults`` names (``variants``: the three 3-D perception variants)."""
    names: list[str] = []
    for name in (n for n in text.split(",") if n):
        expanded = list(VARIANT_FAULTS) if name == "variants" else [canonical_fault(name)]
        for fault in expanded:
            if fault not in ALL_FAULTS:
                raise SystemExit(f"--faults: unknown fault {name!r}; choose from {ALL_FAULTS}")
            names.append(fault)
    return names


def noise_levels(text: str) -> list[float]:
    """The levels ``--noise`` names (a comma list, each within the synthesiser's range)."""
    levels: list[float] = []
    for item in (n.strip() for n in text.split(",") if n.strip()):
        try:
            level = float(item)
        except ValueError:
            raise SystemExit(f"--noise: {item!r} is not a number") from None
        if not (LEVELS.low <= level <= LEVELS.high):  # False for NaN too
            raise SystemExit(f"--noise: {item} is out of range {LEVELS.text()}")
        levels.append(level)
    if not levels:
        raise SystemExit("--noise: give at least one level")
    return levels


@dataclass
class Tally:
    """The outcome of one noise level's runs."""

    confusion: Counter[tuple[str, str]] = field(default_factory=Counter)
    per_scenario: Counter[tuple[str, bool]] = field(default_factory=Counter)
    per_cell: Counter[tuple[str, str, bool]] = field(default_factory=Counter)
    wrong: list[str] = field(default_factory=list)
    #: Diagnosis time per frame (ms) of each log.
    times: list[Timing] = field(default_factory=list)
    #: The whole level: every log synthesised (and written as a bag) and diagnosed.
    whole: Timing = field(default_factory=lambda: Timing(0.0, 0.0))
    skipped: int = 0

    def accuracy(self, fault: str | None = None) -> tuple[int, int]:
        """(correct, total) of one injected fault kind, or of all."""
        cells = [(k, n) for k, n in self.per_cell.items() if fault in (None, k[1])]
        return sum(n for k, n in cells if k[2]), sum(n for _, n in cells)


def run_level(
    args: argparse.Namespace,
    scenarios: list[str],
    faults: list[str],
    noise: float,
    options: dict[str, int],
    scratch: Path,
) -> Tally:
    """Synthesise and diagnose every scenario × fault × seed at noise level ``noise``."""
    tally = Tally()
    with Clock() as clock:
        judge_level(args, scenarios, faults, noise, options, scratch, tally)
    tally.whole = clock.timing
    return tally


def judge_level(
    args: argparse.Namespace,
    scenarios: list[str],
    faults: list[str],
    noise: float,
    options: dict[str, int],
    scratch: Path,
    tally: Tally,
) -> None:
    """``run_level``'s work, counted into ``tally``."""
    for scenario in scenarios:
        for fault in faults:
            for seed in range(args.first, args.first + args.seeds):
                try:
                    log = synthesise(scenario, fault, seed, noise, **options)
                except SynthesisError as error:
                    print(f"skip {scenario} {fault} {seed}: {error}")
                    tally.skipped += 1
                    continue
                if args.drop_2d:
                    drop_2d(log)
                label = log.metadata.raw["synthesis"]
                params = args.params
                if args.without_truth:
                    log, contact_s = without_truth(log)
                    params = replace(params, event_time_s=contact_s)
                if args.bag:
                    log = through_bag(log, args.bag, args.storage, scratch)
                attribution, ms, suspected = diagnose(log, params)
                tally.times.append(ms)
                got = attribution.primary_root_cause or (SUSPECTED if suspected else "none")
                injected = canonical_fault(label["fault"])
                want = fault_module(injected)
                if want == "perception" and got == SUSPECTED:
                    want = SUSPECTED  # named where the evidence allows, else suspected
                tally.confusion[injected, got] += 1
                tally.per_scenario[scenario, got == want] += 1
                tally.per_cell[scenario, injected, got == want] += 1
                if got != want:
                    tally.wrong.append(
                        f"{scenario:20s} {fault:19s} seed {seed:3d}: got {got}"
                        f" (root causes {attribution.root_causes},"
                        f" basis {attribution.attribution_basis!r},"
                        f" reason {attribution.reason})"
                    )


def report_level(tally: Tally, scenarios: list[str], faults: list[str]) -> None:
    """One level's confusion table, accuracy per scenario × fault, per scenario, overall."""
    confusion, per_scenario, per_cell = tally.confusion, tally.per_scenario, tally.per_cell
    width = max(len(x) for x in LABELS) + 2
    print("injected \\ primary".ljust(20) + "".join(x.rjust(width) for x in LABELS))
    for injected in ALL_FAULTS:
        if any(confusion[injected, g] for g in LABELS):
            row = "".join(str(confusion[injected, g]).rjust(width) for g in LABELS)
            print(injected.ljust(20) + row)
    print()
    print("scenario × fault".ljust(46) + "correct")
    for scenario in scenarios:
        for fault in faults:
            ok, bad = per_cell[scenario, fault, True], per_cell[scenario, fault, False]
            if ok + bad:
                cell = f"{scenario} × {fault}".ljust(46)
                print(f"{cell}{ok}/{ok + bad} = {100 * ok / (ok + bad):.1f} %")
    print()
    for scenario in scenarios:
        ok, bad = per_scenario[scenario, True], per_scenario[scenario, False]
        if ok + bad:
            print(f"{scenario:20s} {ok}/{ok + bad} = {100 * ok / (ok + bad):.1f} %")
    total = sum(confusion.values())
    correct = sum(per_scenario[scenario, True] for scenario in scenarios)
    if total:
        print(f"overall accuracy: {correct}/{total} = {100 * correct / total:.1f} %")
        times = tally.times
        wall = sum(t.wall_s for t in times) / len(times)
        cpu = sum(t.cpu_s for t in times) / len(times)
        print(
            f"diagnose: {wall:.2f} ms wall, {cpu:.2f} ms CPU per frame "
            "(oracles + attribution, mean)"
        )
        print(
            f"all {total} logs synthesised and diagnosed: {tally.whole.wall_s:.1f} s wall, "
            f"{tally.whole.cpu_s:.1f} s CPU"
        )
    if tally.wrong:
        print("\nmisattributed:")
        print("\n".join(tally.wrong))


def _percent(counts: tuple[int, int]) -> str:
    ok, total = counts
    return f"{100 * ok / total:.1f} %" if total else "-"


def report_levels(tallies: dict[float, Tally], faults: list[str]) -> None:
    """The accuracy of each fault kind (rows) at each noise level (columns)."""
    levels = list(tallies)
    width = 10
    print("fault kind × noise level (accuracy)")
    print("fault \\ noise".ljust(20) + "".join(f"{k:g}".rjust(width) for k in levels))
    for fault in faults:
        row = "".join(_percent(tallies[k].accuracy(fault)).rjust(width) for k in levels)
        print(fault.ljust(20) + row)
    overall = "".join(_percent(tallies[k].accuracy()).rjust(width) for k in levels)
    print("overall".ljust(20) + overall)
    skipped = "".join(str(tallies[k].skipped).rjust(width) for k in levels)
    print("skipped".ljust(20) + skipped)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("seeds", nargs="?", type=int, default=20)
    parser.add_argument("--first", type=int, default=0, help="first seed")
    parser.add_argument("--scenarios", default=",".join(s for s in SCENARIOS if s != "cruise"))
    parser.add_argument("--faults", default=",".join(FAULTS), help="faults, or 'variants'")
    parser.add_argument(
        "--drop-2d", action="store_true", help="diagnose without bboxes, bboxes_gt and pwp"
    )
    parser.add_argument(
        "--without-truth",
        action="store_true",
        help="diagnose as a real drive: no actors, no collision, event_time_s at the contact",
    )
    parser.add_argument("--bag", choices=PROFILES, help="diagnose each log through a bag")
    parser.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap")
    parser.add_argument(
        "--noise", default="1", help="synthesiser noise levels, comma separated (default 1)"
    )
    parser.add_argument("--actors", type=int, default=None, help="background actors")
    parser.add_argument("--horizon", type=int, default=None, help="prediction/plan steps")
    parser.add_argument(
        "-p",
        "--param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a corrected-mode parameter (as ads-rca diagnose -p), repeatable",
    )
    args = parser.parse_args(argv)
    args.params = corrected_params(args.param)
    scenarios = [s for s in args.scenarios.split(",") if s]
    faults = fault_names(args.faults)
    levels = noise_levels(args.noise)
    options = {
        name: value
        for name, value in (("actors", args.actors), ("horizon", args.horizon))
        if value is not None
    }
    scratch = Path(tempfile.mkdtemp(prefix="accuracy-"))
    atexit.register(shutil.rmtree, scratch, True)
    if len(levels) == 1:
        report_level(
            run_level(args, scenarios, faults, levels[0], options, scratch), scenarios, faults
        )
        return 0
    tallies: dict[float, Tally] = {}
    for level in dict.fromkeys(levels):
        print(f"=== noise level {level:g} ===")
        tally = tallies[level] = run_level(args, scenarios, faults, level, options, scratch)
        report_level(tally, scenarios, faults)
        print()
        print("accuracy per fault kind")
        for fault in faults:
            print(f"{fault:20s} {_percent(tally.accuracy(fault))}")
        print(f"skipped: {tally.skipped}")
        print()
    report_levels(tallies, faults)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
