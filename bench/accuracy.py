"""Attribution accuracy of the `corrected` semantics on synthesised closed-loop logs.

For every scenario × fault over N seeds: synthesise a log, diagnose it with
:func:`ads_rca.engine.diagnose` (corrected mode, exactly what ``ads-rca diagnose`` runs), and
compare the primary root cause with the injected fault its ``metadata.json["synthesis"]``
label names ("none" expects "no fault found"). Prints the confusion table, the
accuracy per scenario and overall, and the misattributed cases (scenario, fault, seed).

Usage: ``python bench/accuracy.py [N] [--scenarios a,b] [--faults x,y] [--first SEED]
[--actors K] [--horizon H]`` (the last two are passed to the synthesiser).
"""

from __future__ import annotations

import argparse
import time
from collections import Counter
from collections.abc import Sequence

from ads_rca.engine import diagnose as diagnose_log
from ads_rca.model import RunLog
from ads_rca.params import make_params
from ads_rca.synth import FAULTS, SCENARIOS, SynthesisError, canonical_fault, synthesise
from ads_rca.verdict import Attribution


def diagnose(log: RunLog) -> tuple[Attribution, float]:
    """The corrected attribution of a log and the diagnosis time per analysed frame (ms)."""
    start = time.perf_counter()
    found = diagnose_log(log, make_params("corrected"))
    per_frame = (time.perf_counter() - start) * 1000 / max(len(found.frames), 1)
    return found.attribution, per_frame


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("seeds", nargs="?", type=int, default=20)
    parser.add_argument("--first", type=int, default=0, help="first seed")
    parser.add_argument("--scenarios", default=",".join(s for s in SCENARIOS if s != "cruise"))
    parser.add_argument("--faults", default=",".join(FAULTS))
    parser.add_argument("--actors", type=int, default=None, help="background actors")
    parser.add_argument("--horizon", type=int, default=None, help="prediction/plan steps")
    args = parser.parse_args(argv)
    scenarios = [s for s in args.scenarios.split(",") if s]
    faults = [f for f in args.faults.split(",") if f]
    options = {
        name: value
        for name, value in (("actors", args.actors), ("horizon", args.horizon))
        if value is not None
    }
    labels = list(FAULTS)  # a fault is named by its module, as the verdict names it
    confusion: Counter[tuple[str, str]] = Counter()
    per_scenario: Counter[tuple[str, bool]] = Counter()
    wrong: list[str] = []
    times: list[float] = []
    for scenario in scenarios:
        for fault in faults:
            for seed in range(args.first, args.first + args.seeds):
                try:
                    log = synthesise(scenario, fault, seed, **options)
                except SynthesisError as error:
                    print(f"skip {scenario} {fault} {seed}: {error}")
                    continue
                attribution, ms = diagnose(log)
                times.append(ms)
                got = attribution.primary_root_cause or "none"
                want = canonical_fault(log.metadata.raw["synthesis"]["fault"])
                confusion[want, got] += 1
                per_scenario[scenario, got == want] += 1
                if got != want:
                    wrong.append(
                        f"{scenario:20s} {fault:11s} seed {seed:3d}: got {got}"
                        f" (root causes {attribution.root_causes},"
                        f" basis {attribution.attribution_basis!r},"
                        f" reason {attribution.reason})"
                    )
    width = max(len(x) for x in labels) + 2
    print("injected \\ primary".ljust(20) + "".join(x.rjust(width) for x in labels))
    for want in labels:
        if any(confusion[want, g] for g in labels):
            row = "".join(str(confusion[want, g]).rjust(width) for g in labels)
            print(want.ljust(20) + row)
    print()
    for scenario in scenarios:
        ok, bad = per_scenario[scenario, True], per_scenario[scenario, False]
        if ok + bad:
            print(f"{scenario:20s} {ok}/{ok + bad} = {100 * ok / (ok + bad):.1f} %")
    total = sum(confusion.values())
    correct = sum(confusion[x, x] for x in labels)
    if total:
        print(f"overall accuracy: {correct}/{total} = {100 * correct / total:.1f} %")
        print(f"diagnose: {sum(times) / len(times):.2f} ms per frame (oracles + attribution, mean)")
    if wrong:
        print("\nmisattributed:")
        print("\n".join(wrong))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
