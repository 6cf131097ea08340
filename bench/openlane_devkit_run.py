"""The OpenLane-V2 devkit's side of ``bench_openlane_devkit.py``: run inside the devkit's own
environment (openlanev2 2.1.0, numpy < 1.24), never in ours.

    DEVKIT_PYTHON bench/openlane_devkit_run.py ROOT [--segment NAME ...]

``ROOT`` is a split written by ``test/writers/openlane_released.py``. As the official val/test
evaluation does, ``collect(ROOT, data_dict, collection, point_interval=20)`` pickles the
ground truth, then ``evaluate(ground_truth=<that pickle>, predictions=<results pickle>)``
scores the model's results (``results.json`` made into the devkit's dict and pickled here:
a pickle from our numpy 2 would not load under numpy 1.23). Once for the whole split and
once per ``--segment``. Prints one JSON object: the figures per scope, the evaluation's
wall and CPU seconds, and the packages' versions.

The devkit's ``f_score`` imports ``ortools.graph.pywrapgraph``, which ortools dropped in 9.4;
the devkit pins ortools 9.2, which has no wheel for Python 3.11. Where it is missing, a small
adapter over ``ortools.graph.python.min_cost_flow`` (the same solver, renamed methods) stands
in for it. It only serves the F-score for 3-D lanes, which none of the compared figures uses.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import json
import pickle
import sys
import time
import types
from pathlib import Path
from typing import Any

# The generator needs only numpy and the standard library, so it is imported here too.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "test"))

from writers.openlane_released import (
    DATA_DICT,
    POINT_INTERVAL,
    RESULTS,
    SPLIT,
    devkit_results,
)

PACKAGES = (
    "openlanev2",
    "numpy",
    "scipy",
    "shapely",
    "similaritymeasures",
    "ortools",
    "opencv-python-headless",
    "tqdm",
    "iso3166",
)


def pywrapgraph_stand_in() -> bool:
    """Make ``from ortools.graph import pywrapgraph`` work; True if the adapter was needed."""
    try:
        from ortools.graph import pywrapgraph  # noqa: F401
    except ImportError:
        pass
    else:
        return False
    import ortools.graph
    from ortools.graph.python import min_cost_flow

    class SimpleMinCostFlow:
        """pywrapgraph's names for the methods ``f_score.SolveMinCostFlow`` calls."""

        OPTIMAL = min_cost_flow.SimpleMinCostFlow.OPTIMAL

        def __init__(self) -> None:
            self._solver = min_cost_flow.SimpleMinCostFlow()

        def AddArcWithCapacityAndUnitCost(self, tail: int, head: int, cap: int, cost: int) -> int:
            return int(self._solver.add_arc_with_capacity_and_unit_cost(tail, head, cap, cost))

        def SetNodeSupply(self, node: int, supply: int) -> None:
            self._solver.set_node_supply(node, supply)

        def Solve(self) -> Any:
            return self._solver.solve()

        def NumArcs(self) -> int:
            return int(self._solver.num_arcs())

        def Tail(self, arc: int) -> int:
            return int(self._solver.tail(arc))

        def Head(self, arc: int) -> int:
            return int(self._solver.head(arc))

        def Flow(self, arc: int) -> int:
            return int(self._solver.flow(arc))

        def UnitCost(self, arc: int) -> int:
            return int(self._solver.unit_cost(arc))

    module = types.ModuleType("ortools.graph.pywrapgraph")
    module.SimpleMinCostFlow = SimpleMinCostFlow  # type: ignore[attr-defined]
    sys.modules[module.__name__] = module
    ortools.graph.pywrapgraph = module
    return True


def figures(metrics: dict[str, Any]) -> dict[str, float]:
    """The devkit's OpenLane-V2 Score part, by our figure names (and its F-score)."""
    score = metrics["OpenLane-V2 Score"]
    return {
        "det_l": float(score["DET_l"]),
        "det_t": float(score["DET_t"]),
        "top_ll": float(score["TOP_ll"]),
        "top_lt": float(score["TOP_lt"]),
        "ols": float(score["score"]),
        "f_score": float(metrics["F-Score for 3D Lane"]["score"]),
    }


def scope(root: Path, name: str, segments: list[str] | None) -> dict[str, Any]:
    """Collect and evaluate the frames of ``segments`` (all if None) as collection ``name``."""
    from openlanev2.centerline.evaluation import evaluate
    from openlanev2.centerline.preprocessing import collect

    index = json.loads((root / DATA_DICT).read_text(encoding="utf-8"))
    if segments is not None:
        index = {SPLIT: {s: index[SPLIT][s] for s in segments}}
    collect(str(root), index, name, point_interval=POINT_INTERVAL)
    document = json.loads((root / RESULTS).read_text(encoding="utf-8"))
    results = root / f"{name}_results.pkl"
    results.write_bytes(pickle.dumps(devkit_results(document, segments)))
    wall, cpu = time.perf_counter(), time.process_time()
    metrics = evaluate(
        ground_truth=str(root / f"{name}.pkl"), predictions=str(results), verbose=False
    )
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    frames = sum(len(v) for v in index[SPLIT].values())
    return {"figures": figures(metrics), "frames": frames, "wall_s": wall, "cpu_s": cpu}


def f_score_seconds(root: Path, name: str) -> tuple[float, float]:
    """Wall and CPU seconds of the F-score alone on collection ``name`` (part of
    ``evaluate``'s time, not of the OpenLane-V2 Score)."""
    from openlanev2.centerline.evaluation.f_score import f1

    truth = pickle.loads((root / f"{name}.pkl").read_bytes())
    results = pickle.loads((root / f"{name}_results.pkl").read_bytes())["results"]
    gts = {k: v["annotation"] for k, v in truth.items()}
    preds = {k: results[k]["predictions"] for k in truth}
    wall, cpu = time.perf_counter(), time.process_time()
    f1.bench_one_submit(gts=gts, preds=preds)
    return time.perf_counter() - wall, time.process_time() - cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("root", type=Path)
    parser.add_argument("--segment", action="append", default=[], help="also score it alone")
    args = parser.parse_args()
    stand_in = pywrapgraph_stand_in()
    out: dict[str, Any] = {"split": scope(args.root, SPLIT, None), "segments": {}}
    out["split"]["f_score_wall_s"], out["split"]["f_score_cpu_s"] = f_score_seconds(
        args.root, SPLIT
    )
    for segment in args.segment:
        out["segments"][segment] = scope(args.root, f"{SPLIT}_{segment}", [segment])
    out["environment"] = {
        "python": sys.version.split()[0],
        **{p: importlib.metadata.version(p) for p in PACKAGES},
        "pywrapgraph": "adapter over ortools.graph.python.min_cost_flow" if stand_in else "ortools",
    }
    print(json.dumps(out))


if __name__ == "__main__":
    main()
