"""The whole crash grid in stack mode over real DDS (issue #15): verdicts and frames vs diagnose.

    python bench/bench_stack_grid.py [--modes reference corrected] [--drop bboxes]
                                     [--scenarios cut_in ...] [--faults perception ...]

For every synthesised crash (4 scenarios x 4 faults, seed 1, or those of ``--scenarios``
and ``--faults``) and mode, the ``monitors``
and ``aggregator`` nodes run in stack mode (each its own process) beside the test stack
(``test/stack_publisher.py``: per-topic stamp offsets up to 20 ms, jitter, no markers, no
metadata). Two rounds: no loss (the verdict and every judged frame compared with
``diagnose``), and 2 % of ``--drop``'s messages dropped (the dropped frames must be the
ones reported incomplete; the verdict's attribution compared). Prints a row per run (its
wall time and CPU time: this process's and the node and stack processes', start to exit)
and the fractions. The test suite runs a diagonal of this grid over DDS
(test/test_stack_graph.py) and the whole grid in-process (test/test_stack_mode.py); this
is the whole grid over DDS, too long for every CI run (about 10 s a run).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from timing import Clock

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "test"))

from stackgraph import (
    latest_results,
    metrics_difference,
    run_stack_graph,
    same_verdict,
)

from ads_rca.diagnosis.engine import diagnose
from ads_rca.params import make_params
from ads_rca.ros.env import pick_domain_id, ros_environment
from ads_rca.ros.launcher import ParamValue
from ads_rca.synth import synthesise

SCENARIOS = ("cut_in", "lead_braking", "pedestrian_crossing", "left_turn")
FAULTS = ("perception", "prediction", "planning", "controller")
RUN_FACTS: dict[str, ParamValue] = {
    "timesteps_per_frame": 50,
    "camera_loc.x": 1.3,
    "camera_loc.z": 1.8,
}
ATTRIBUTION = ("primary_root_cause", "root_causes", "contributing", "partner_id")


def one(work: Path, scenario: str, fault: str, mode: str, drop: str | None) -> tuple[bool, str]:
    """(verdict as diagnose's, what else was checked) for one run."""
    log = synthesise(scenario, fault, 1)
    offline = diagnose(log, make_params(mode))
    env = ros_environment(domain_id=pick_domain_id(), log_dir=work / "ros_log")
    namespace = f"/bench_{scenario}_{fault}"
    options = ["--namespace", namespace, "--seed", "3"]
    params: dict[str, ParamValue] = {"semantics": mode, "topic_namespace": namespace}
    params |= RUN_FACTS
    if drop:
        options += ["--drop", f"{drop}:0.02"]
        params["input_timeout_s"] = 1.0
    else:
        params["history_frames"] = 400
    run = run_stack_graph(env, work, f"{scenario}:{fault}:1", params, options)
    [verdict] = run.verdicts
    want = offline.to_json()
    judged = latest_results(run.results)
    if drop:
        flagged = {s for (m, s), r in judged.items() if f"no {drop} record" in r.incomplete}
        dropped = set(run.publisher["dropped"][drop])
        same = all(verdict[k] == want[k] for k in ATTRIBUTION)
        return same, f"dropped {sorted(dropped)} flagged {'==' if flagged == dropped else '!='}"
    frames = sum(
        metrics_difference(r.metrics, judged[(m, f.timestamp_ms)].result.metrics) is None
        for f in offline.frames
        for m, r in f.results.items()
        if (m, f.timestamp_ms) in judged
    )
    total = sum(len(f.results) for f in offline.frames)
    return same_verdict(verdict, want), f"frames equal {frames}/{total}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--modes", nargs="+", default=["reference", "corrected"])
    parser.add_argument("--drop", default="bboxes")
    parser.add_argument("--scenarios", nargs="+", choices=SCENARIOS, default=list(SCENARIOS))
    parser.add_argument("--faults", nargs="+", choices=FAULTS, default=list(FAULTS))
    args = parser.parse_args()
    for drop in (None, args.drop):
        title = f"2 % of {drop} dropped" if drop else "no loss"
        print(
            f"\n{title}\n{'mode':10} {'scenario':20} {'fault':11} {'verdict':8} {'wall s':>6} "
            f"{'CPU s':>6}  checked"
        )
        for mode in args.modes:
            same = 0
            for scenario in args.scenarios:
                for fault in args.faults:
                    with Clock() as took, tempfile.TemporaryDirectory() as work:
                        ok, note = one(Path(work), scenario, fault, mode, drop)
                    same += ok
                    print(
                        f"{mode:10} {scenario:20} {fault:11} {'same' if ok else 'DIFF':8} "
                        f"{took.wall_s:6.1f} {took.cpu_s:6.1f}  {note}",
                        flush=True,
                    )
            runs = len(args.scenarios) * len(args.faults)
            print(f"{mode}: {same}/{runs} verdicts equal diagnose")


if __name__ == "__main__":
    main()
