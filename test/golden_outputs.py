"""Golden outputs: ``ads-rca diagnose --json`` on every log we can make, stored to compare.

Why: a redesign step must not change any verdict. This helper
writes the bundled example and a synthesised log of every scenario × fault (seed 1) into a
scratch folder, runs the real CLI on each in both modes (separate processes,
``PYTHONHASHSEED=0``, the log given by a relative path so ``source`` does not name the
scratch folder) and keeps each JSON file's sha256 and parsed text.
``test_diagnosis_golden_outputs.py`` compares them with ``test/golden/diagnose_outputs.json.gz``.

Byte equality holds on one machine but not across CPUs: numpy evaluates float64 ``sin``,
``cos``, ``arctan2``... with other code on AVX-512 machines (Intel's SVML) than elsewhere
(libm), so the corrected mode's metrics differ in their last bits between two CI machines.
Where the bytes differ, the comparison is therefore exact for everything but floats, and
floats must agree to ``REL_TOL``: far below any threshold, far above a last-bit difference.

    python test/golden_outputs.py            # print the hashes as JSON
    python test/golden_outputs.py --write    # store the outputs (only when a change is intended)
"""

from __future__ import annotations

import argparse
import gzip
import hashlib
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from ads_rca.params import SEMANTICS
from ads_rca.sources.log.writer import write_run_log
from ads_rca.synth import FAULTS, SCENARIOS, synthesise

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "examples" / "cut_in_perception"
STORED = Path(__file__).resolve().parent / "golden" / "diagnose_outputs.json.gz"
SEED = 1
REL_TOL = 1e-9
ABS_TOL = 1e-12
#: Log folder names as the hashes were recorded (the controller fault was spelt "control"
#: then): the folder name is the JSON's ``source``, so it must not change with the spelling.
RECORDED_NAME = {"controller": "control"}


def cases() -> list[tuple[str, str]]:
    """Every scenario × fault the synthesiser accepts (cruise never crashes: no fault)."""
    return [(s, f) for s in SCENARIOS for f in FAULTS if s != "cruise" or f == "none"]


def make_logs(folder: Path) -> list[str]:
    """The example and every synthesised log, as folder names under ``folder``."""
    shutil.copytree(EXAMPLE, folder / "example")
    names = ["example"]
    for scenario, fault in cases():
        name = f"synth_{scenario}_{RECORDED_NAME.get(fault, fault)}"
        write_run_log(synthesise(scenario, fault, SEED), folder / name)
        names.append(name)
    return names


def outputs() -> dict[str, dict[str, object]]:
    """``{"<log>/<semantics>": {"sha256": ..., "json": parsed}}`` of diagnose --json,
    for every log and mode."""
    env = {**os.environ, "PYTHONHASHSEED": "0"}
    out: dict[str, dict[str, object]] = {}
    with tempfile.TemporaryDirectory(prefix="golden_") as scratch:
        folder = Path(scratch)
        for name in make_logs(folder):
            for semantics in SEMANTICS:
                target = folder / f"{name}.{semantics}.json"
                options = ["--semantics", semantics, "--workers", "1", "--json", str(target)]
                subprocess.run(
                    [sys.executable, "-m", "ads_rca.cli", "diagnose", name, *options],
                    cwd=folder,
                    env=env,
                    check=True,
                    capture_output=True,
                )
                data = target.read_bytes()
                out[f"{name}/{semantics}"] = {
                    "sha256": hashlib.sha256(data).hexdigest(),
                    "json": json.loads(data),
                }
    return out


def stored() -> dict[str, dict[str, object]]:
    """The outputs recorded with ``--write``."""
    with gzip.open(STORED, "rt", encoding="utf-8") as handle:
        loaded: dict[str, dict[str, object]] = json.load(handle)
    return loaded


def first_difference(old: object, new: object, where: str = "") -> str | None:
    """The JSON Pointer of the first place ``new`` differs from ``old`` (floats to REL_TOL),
    or None."""
    if isinstance(old, float) and isinstance(new, float):
        close = math.isclose(old, new, rel_tol=REL_TOL, abs_tol=ABS_TOL)
        return None if close else f"{where}: {old!r} -> {new!r}"
    if type(old) is not type(new):
        return f"{where}: {old!r} -> {new!r}"
    if isinstance(old, dict) and isinstance(new, dict):
        if list(old) != list(new):
            return f"{where}: keys {list(old)} -> {list(new)}"
        for key in old:
            found = first_difference(old[key], new[key], f"{where}/{key}")
            if found:
                return found
        return None
    if isinstance(old, list) and isinstance(new, list):
        if len(old) != len(new):
            return f"{where}: {len(old)} items -> {len(new)}"
        for index, (a, b) in enumerate(zip(old, new, strict=True)):
            found = first_difference(a, b, f"{where}/{index}")
            if found:
                return found
        return None
    return None if old == new else f"{where}: {old!r} -> {new!r}"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help=f"store the hashes in {STORED}")
    args = parser.parse_args()
    now = outputs()
    if args.write:
        STORED.parent.mkdir(exist_ok=True)
        text = json.dumps(now, separators=(",", ":"))  # key order is part of the output
        STORED.write_bytes(gzip.compress(text.encode(), compresslevel=9, mtime=0))
    hashes = {key: value["sha256"] for key, value in now.items()}
    sys.stdout.write(json.dumps(hashes, indent=1, sort_keys=True) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
