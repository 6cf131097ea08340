"""Attribution accuracy of the `corrected` semantics in a world we did not build: Eclipse SUMO.

bench/accuracy.py measures the attribution on our synthesiser's worlds; here the world comes
from SUMO (``bench/sumo_world``): road networks built by ``netconvert`` (curves, an on-ramp,
a junction with its turning arcs, a crossing), dense traffic driven by SUMO's Krauss
car-following and LC2013 lane-changing models, one partner whose manoeuvre SUMO performs.
Only the ego's small stack (``ads_rca.synth``'s camera, detector, tracker, predictor,
planner, controller, run in closed loop against SUMO's recorded road users) and the injected
fault are ours. The runs obey the synthesiser's fairness rules (the fault-free twin does not
crash and reacts to the partner, every module fault crashes into it, the onset comes from
the twin's reaction) and are written as ``ads-rca synth`` writes a log folder, with
``metadata.json["synthesis"]`` naming the family, fault, seed and ``"world": "sumo <ver>"``.

For every family × fault over N seeds: build the set (cached under
``~/.cache/ads_rca/sumo-logs/<key>``, the key naming SUMO's version, frames, horizon, noise
and a hash of bench/sumo_world's code), diagnose each log with
:func:`ads_rca.diagnosis.engine.diagnose` (corrected mode) read back from its folder, and
print the confusion table (injected × named), the accuracy per family × fault, the
fault-free results, every miss with family, fault, seed and the verdict's reason (its
``reason``, basis and each module's first failing frame), the scenes SUMO could not give,
and the wall and CPU time of building and of diagnosing (CPU includes SUMO's processes).

Usage: ``python bench/accuracy_sumo.py [N] [--families a,b] [--faults x,y] [--noise K]
[--first SEED] [--venv DIR] [--rebuild]`` (``--faults`` as bench/accuracy.py's, default the
four module faults, the three perception variants and none).
"""

from __future__ import annotations

import argparse
import shutil
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from accuracy import SUSPECTED, Tally, drop_2d, fault_names, report_level
from sumo_world.env import DEFAULT_VENV, binary_version, ensure_sumo
from sumo_world.families import FAMILIES
from sumo_world.runs import LOGS, Outcome, build_seed, cache_key
from timing import Clock, Timing, timed

from ads_rca.diagnosis.engine import diagnose
from ads_rca.params import make_params
from ads_rca.sources.log.reader import read_run_log
from ads_rca.synth import FAULTS, VARIANT_FAULTS, canonical_fault, fault_module
from ads_rca.synth.noise import LEVELS, Noise

#: The families run unless ``--families`` says otherwise.
DEFAULT_FAMILIES = FAMILIES


def judge(outcome: Outcome, params: Any, three_d: bool = False) -> tuple[str, str, Timing, int]:
    """The primary root cause named for ``outcome``'s log ("none", or ``suspected``), a
    one-line account of the verdict, the diagnosis time and the frames analysed.
    ``three_d``: judged as a 3-D stack's recording (bench/accuracy.py ``--drop-2d``), which is
    where the perception variants (a shifted, shrunk or wrong-velocity 3-D object) show."""
    assert outcome.folder is not None
    log = read_run_log(outcome.folder)
    if three_d:
        drop_2d(log)
    found, took = timed(lambda: diagnose(log, params))
    attribution = found.attribution
    suspected = attribution.primary_root_cause is None and bool(found.conclusion.suspected)
    got = attribution.primary_root_cause or (SUSPECTED if suspected else "none")
    document = found.to_json()
    firsts = {
        module: entry.get("first_failure_frame")
        for module, entry in (document.get("modules") or {}).items()
        if isinstance(entry, dict)
    }
    failing = ", ".join(f"{m} {f}" for m, f in firsts.items() if f is not None) or "none"
    account = (
        f"root causes {attribution.root_causes}, basis {attribution.attribution_basis!r}, "
        f"reason {attribution.reason!r}, first failing frames: {failing}; "
        f"collision {document.get('collision')!r} at frame {document.get('collision_frame')}"
    )
    return got, account, took, max(len(found.frames), 1)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("seeds", nargs="?", type=int, default=4)
    parser.add_argument("--first", type=int, default=0, help="first seed")
    parser.add_argument("--families", default=",".join(DEFAULT_FAMILIES))
    parser.add_argument(
        "--faults", default=",".join([*FAULTS, *VARIANT_FAULTS]), help="faults, or 'variants'"
    )
    parser.add_argument("--noise", type=float, default=1.0, help="synthesiser noise level K")
    parser.add_argument("--venv", type=Path, default=DEFAULT_VENV, help="SUMO's venv")
    parser.add_argument("--rebuild", action="store_true", help="ignore the cached set")
    parser.add_argument(
        "--drop-2d",
        action="store_true",
        help="judge each log without its 2-D boxes and predictions on truth (a 3-D stack)",
    )
    args = parser.parse_args(argv)
    families = [f for f in args.families.split(",") if f]
    unknown = sorted(set(families) - set(FAMILIES))
    if unknown:
        raise SystemExit(f"--families: unknown {unknown}; choose from {', '.join(FAMILIES)}")
    faults = fault_names(args.faults)
    if not LEVELS.low <= args.noise <= LEVELS.high:
        raise SystemExit(f"--noise: {args.noise} is out of range {LEVELS.text()}")
    sumo = ensure_sumo(args.venv)
    root = LOGS / cache_key(200, 30, args.noise)
    if args.rebuild:
        shutil.rmtree(root, ignore_errors=True)
    seeds = range(args.first, args.first + args.seeds)
    print(f"world: {binary_version(sumo)}; set: {root}")

    outcomes: list[Outcome] = []
    with Clock() as building:
        for family in families:
            for seed in seeds:
                outcomes += build_seed(sumo, family, seed, faults, root, Noise(args.noise))
    made = [o for o in outcomes if o.folder is not None]
    refused = [o for o in outcomes if o.folder is None]

    params = make_params("corrected")
    tally = Tally()
    per_frame: list[Timing] = []
    clean: Counter[tuple[str, str]] = Counter()
    with Clock() as diagnosing:
        for outcome in made:
            got, account, took, frames = judge(outcome, params, args.drop_2d)
            per_frame.append(Timing(took.wall_s * 1000 / frames, took.cpu_s * 1000 / frames))
            tally.times.append(per_frame[-1])
            injected = canonical_fault(outcome.fault)
            want = fault_module(injected)
            if want == "perception" and got == SUSPECTED:
                want = SUSPECTED
            tally.confusion[injected, got] += 1
            tally.per_scenario[outcome.family, got == want] += 1
            tally.per_cell[outcome.family, injected, got == want] += 1
            if injected == "none":
                clean[outcome.family, got] += 1
            if got != want:
                label = outcome.label
                tally.wrong.append(
                    f"{outcome.family:13s} {outcome.fault:19s} seed {outcome.seed:3d} "
                    f"(attempt {label.get('attempt')}, onset {label.get('fault_onset_frame')}, "
                    f"contact {label.get('collision_frame')}): got {got}; {account}"
                )
    tally.whole = building.timing + diagnosing.timing

    print()
    report_level(tally, families, faults)
    print()
    print("fault-free runs (expected: no module named)")
    for family in families:
        named = {g: n for (f, g), n in clean.items() if f == family}
        total = sum(named.values())
        if total:
            words = ", ".join(f"{g}: {n}" for g, n in sorted(named.items()))
            print(f"  {family:13s} {total} runs: {words}")
    print()
    print(f"refused (no acceptable SUMO scene): {len(refused)} of {len(outcomes)}")
    reasons: Counter[tuple[str, str]] = Counter()
    for outcome in refused:
        reasons[outcome.family, outcome.fault] += 1
    for (family, fault), count in sorted(reasons.items()):
        example = next(o for o in refused if o.family == family and o.fault == fault)
        print(f"  {family:13s} {fault:19s} {count}× e.g. seed {example.seed}: {example.refused}")
    print()
    build_t, diag_t = building.timing, diagnosing.timing
    print(
        f"build: {len(outcomes)} family × fault × seed runs ({len(made)} logs) in "
        f"{build_t.wall_s:.1f} s wall, {build_t.cpu_s:.1f} s CPU (SUMO's processes included)"
    )
    print(
        f"diagnose: {len(made)} logs in {diag_t.wall_s:.1f} s wall, {diag_t.cpu_s:.1f} s CPU "
        "(read back from their folders, corrected mode)"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
