"""The official OpenLane-V2 devkit judges our OpenLane-V2 figures, on data shaped like the
released files; and how long each takes per frame.

    python bench/bench_openlane_devkit.py [--venv DIR] [--python PY] [--cases NAME ...]
                                          [--dir DIR] [--repeat 5] [--pin FILE]

Why: docs/openlane-metrics.md restates the devkit's rules and our tests check them on
hand-made frames; only the devkit itself can say our numbers are the leaderboard's, and only
on frames like the released ones (201-point lanes thinned by the val/test ``collect``, 60+
lanes, ~200 predicted lanes in the baseline's format). The devkit is not our dependency (it
pins numpy < 1.24 and more): it runs in its own venv, built here once (``--venv``, default
~/.cache/ads_rca/openlane-devkit-venv) from :data:`RECIPE` plus ``openlanev2==2.1.0
--no-deps``, so only what ``openlanev2.centerline.evaluation`` and ``preprocessing.collect``
import is installed.

For each case of test/writers/openlane_released.py (a temporary split, or under ``--dir``):

- the devkit (bench/openlane_devkit_run.py in its venv): ``collect(root, data_dict, 'val',
  point_interval=20)`` and ``evaluate(ground_truth=<pkl>, predictions=<results pkl>)``, on
  the whole split and on each segment alone;
- ours, as users reach it: the split through the reader and ``score_frames(...,
  devkit_empty=True)`` (the devkit's empty-class rules), and each segment through
  ``python -m ads_rca.cli diagnose SEGMENT --format openlane --predictions DIR --json``
  (the default rules: every segment holds all 13 attributes, so they agree with the
  devkit's there).

It prints each figure's devkit value, ours, their difference and whether it is within
:data:`TOLERANCE` (the devkit works in float32), then the scoring time per frame, wall and
CPU: ours (``score_frames`` alone, the median of ``--repeat``) and the devkit's
(``evaluate``, which includes its F-score for 3-D lanes, shown apart). ``--pin FILE`` writes
the devkit's figures per case with the generator's parameters and the devkit's environment
(test/golden/openlane_devkit_2_1_0.json, what test_sources_openlane_devkit_parity.py holds
ours to).
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from timing import Clock, Timing, median

# The dataset writers live with the tests (not in the installed package).
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "test"))

from writers.openlane_released import (
    CASES,
    FIGURES,
    POINT_INTERVAL,
    SEGMENTS,
    SPLIT,
    cli_scores,
    parameters,
    scored_pairs,
    write_released_split,
)

from ads_rca.sources.openlane.scores import score_frames

DEVKIT = "openlanev2==2.1.0"
#: What the devkit's evaluation and collect import, as versions that install on Python 3.11.
#: The devkit pins scipy 1.8.0 and ortools 9.2.9972, which have no wheel for 3.11: scipy
#: 1.9.3 is the first that has, ortools 9.5.2237 the first that has (9.2 is not even on the
#: registry), and it no longer has ``pywrapgraph`` (the runner's adapter stands in; only the
#: F-score uses it). numpy 1.23.5 is the newest below the devkit's < 1.24. io.py imports cv2:
#: the headless opencv build. protobuf and absl-py as ortools 9.5 was built against.
RECIPE = (
    "numpy==1.23.5",
    "scipy==1.9.3",
    "shapely==2.0.0",
    "similaritymeasures==1.1.0",
    "tqdm==4.66.1",
    "iso3166==2.1.1",
    "ortools==9.5.2237",
    "protobuf==4.21.12",
    "absl-py==2.1.0",
    "opencv-python-headless==4.8.1.78",
)
DEFAULT_VENV = Path.home() / ".cache" / "ads_rca" / "openlane-devkit-venv"
RUNNER = Path(__file__).resolve().parent / "openlane_devkit_run.py"
MARKER = "ads_rca-devkit-recipe.json"
TOLERANCE = 1e-6
NAMES = {"det_l": "DET_l", "det_t": "DET_t", "top_ll": "TOP_ll", "top_lt": "TOP_lt", "ols": "OLS"}
#: The case whose frames are timed (real-sized: 60+ true lanes, 200 predicted).
TIMED_CASE = "baseline_noisy"


def devkit_python(venv: Path, python: str) -> Path:
    """The devkit venv's interpreter, the venv built first if missing or of another recipe."""
    wanted = {"python": python, "recipe": list(RECIPE), "devkit": DEVKIT}
    marker = venv / MARKER
    interpreter = venv / "bin" / "python"
    built = marker.exists() and json.loads(marker.read_text(encoding="utf-8")) == wanted
    if built and interpreter.exists():
        return interpreter
    print(f"building the devkit's venv in {venv} ...", flush=True)
    venv.parent.mkdir(parents=True, exist_ok=True)
    subprocess.run([python, "-m", "venv", "--clear", str(venv)], check=True)
    pip = [str(interpreter), "-m", "pip", "install", "--quiet", "--disable-pip-version-check"]
    subprocess.run([*pip, *RECIPE], check=True)
    subprocess.run([*pip, "--no-deps", DEVKIT], check=True)
    marker.write_text(json.dumps(wanted), encoding="utf-8")
    return interpreter


def run_devkit(interpreter: Path, root: Path) -> dict[str, Any]:
    """The devkit's figures on the split and on each segment (bench/openlane_devkit_run.py)."""
    segments = [arg for s in SEGMENTS for arg in ("--segment", s.name)]
    done = subprocess.run(
        [str(interpreter), str(RUNNER), str(root), *segments],
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode != 0:
        raise SystemExit(f"the devkit failed on {root}:\n{done.stderr[-3000:]}")
    found: dict[str, Any] = json.loads(done.stdout)
    return found


def ours(root: Path, repeat: int) -> tuple[dict[str, Any], dict[str, dict[str, Any]], Timing]:
    """Our split figures (reader + ``score_frames(..., devkit_empty=True)``), each segment's
    through the CLI, and the median time of ``score_frames`` per frame."""
    pairs = scored_pairs(root)
    timings = []
    for _ in range(max(repeat, 1)):
        with Clock() as clock:
            scores = score_frames(pairs, devkit_empty=True)
        timings.append(clock.timing)
    spent = median(timings)
    per_frame = Timing(spent.wall_s / len(pairs), spent.cpu_s / len(pairs))
    segments = {s.name: cli_scores(root, s, root / f"verdict_{s.name}.json") for s in SEGMENTS}
    return scores.to_dict(), segments, per_frame


def difference(devkit: float, found: object) -> float:
    """|devkit - ours|; NaN when ours is not a number (undefined, or missing)."""
    if isinstance(found, bool) or not isinstance(found, int | float):
        return math.nan
    return abs(devkit - float(found))


def rows(
    case: str, devkit: dict[str, Any], split: dict[str, Any], cli: dict[str, Any]
) -> list[str]:
    """The table's lines of one case: the split, then each segment through the CLI."""
    scopes = [("split", devkit["split"]["figures"], split)]
    scopes += [(f"{name} (CLI)", devkit["segments"][name]["figures"], cli[name]) for name in cli]
    lines = []
    for scope, theirs, mine in scopes:
        for key in FIGURES:
            gap = difference(theirs[key], mine.get(key))
            shown = mine.get(key)
            value = f"{shown:.9f}" if isinstance(shown, float) else str(shown)
            verdict = "yes" if gap <= TOLERANCE else "NO"
            lines.append(
                f"{case:<21}{scope:<13}{NAMES[key]:<7}{theirs[key]:>13.9f}{value:>13}"
                f"{gap:>12.2e}  {verdict}"
            )
    return lines


def pinned(devkit: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """The golden file: the devkit's figures per case and where they came from."""
    environment = next(iter(devkit.values()))["environment"]
    return {
        "about": (
            "The OpenLane-V2 devkit's figures on test/writers/openlane_released.py's cases, "
            "written by bench/bench_openlane_devkit.py --pin; "
            "test_sources_openlane_devkit_parity.py holds ours to them."
        ),
        "devkit": {"package": "openlanev2", "version": environment["openlanev2"]},
        "numpy": environment["numpy"],
        "environment": environment,
        "split_rule": {
            "split": SPLIT,
            "point_interval": POINT_INTERVAL,
            "collect": f"collect(root, data_dict, '{SPLIT}', point_interval={POINT_INTERVAL})",
            "evaluate": "evaluate(ground_truth=<collect's pkl>, predictions=<results pkl>)",
        },
        "tolerance": TOLERANCE,
        "generator": parameters(),
        "cases": {
            case: {
                "split": {k: found["split"]["figures"][k] for k in FIGURES},
                "segments": {
                    name: {k: scope["figures"][k] for k in FIGURES}
                    for name, scope in found["segments"].items()
                },
            }
            for case, found in devkit.items()
        },
    }


def devkit_times(found: dict[str, Any], frames: int) -> dict[str, Timing]:
    """The devkit's ``evaluate`` per frame on the split, and its F-score part."""
    split = found["split"]
    whole = Timing(split["wall_s"] / frames, split["cpu_s"] / frames)
    f_score = Timing(split["f_score_wall_s"] / frames, split["f_score_cpu_s"] / frames)
    return {
        "devkit evaluate()": whole,
        "  of which F-score for 3-D lanes": f_score,
        "  OpenLane-V2 Score part": Timing(
            whole.wall_s - f_score.wall_s, whole.cpu_s - f_score.cpu_s
        ),
    }


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--venv", type=Path, default=DEFAULT_VENV, help="the devkit's venv")
    parser.add_argument("--python", default=sys.executable, help="interpreter of a new venv")
    parser.add_argument("--cases", nargs="+", choices=sorted(CASES), default=list(CASES))
    parser.add_argument("--dir", type=Path, help="keep the data here (default: a temp dir)")
    parser.add_argument("--repeat", type=int, default=5, help="timed runs of ours")
    parser.add_argument("--pin", type=Path, help="write the devkit's figures here (JSON)")
    args = parser.parse_args()
    interpreter = devkit_python(args.venv, args.python)
    with tempfile.TemporaryDirectory(prefix="openlane-devkit-") as scratch:
        base = args.dir or Path(scratch)
        devkit: dict[str, dict[str, Any]] = {}
        lines: list[str] = []
        timed: dict[str, Timing] = {}
        for name in args.cases:
            root = base / name
            found = write_released_split(root, CASES[name])
            devkit[name] = run_devkit(interpreter, root)
            split, cli, per_frame = ours(root, args.repeat)
            lines += rows(name, devkit[name], split, cli)
            if name == TIMED_CASE or not timed:
                timed = {
                    "ours: score_frames()": per_frame,
                    **devkit_times(devkit[name], len(found)),
                }
    print(
        f"{'case':<21}{'scope':<13}{'figure':<7}{'devkit':>13}{'ours':>13}{'|diff|':>12}  "
        f"within {TOLERANCE:g}"
    )
    print("\n".join(lines))
    failed = sum(line.endswith("NO") for line in lines)
    print(f"{len(lines) - failed} of {len(lines)} figures within {TOLERANCE:g}")
    environment = next(iter(devkit.values()))["environment"]
    print(f"devkit environment: {json.dumps(environment)}")
    print(
        f"time per frame ({TIMED_CASE if TIMED_CASE in devkit else args.cases[0]}): wall s, CPU s"
    )
    for label, spent in timed.items():
        print(f"  {label:<34}{spent.wall_s:>10.4f}{spent.cpu_s:>10.4f}")
    if args.pin:
        args.pin.write_text(json.dumps(pinned(devkit), indent=1) + "\n", encoding="utf-8")
        print(f"pinned: {args.pin}")


if __name__ == "__main__":
    main()
