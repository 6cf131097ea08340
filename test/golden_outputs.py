"""Golden outputs: the sha256 of ``ads-rca diagnose --json`` on every log we can make.

Why: a redesign step (issue #13) must not change any verdict, byte for byte. This helper
writes the bundled example and a synthesised log of every scenario × fault (seed 1) into a
scratch folder, runs the real CLI on each in both modes (separate processes,
``PYTHONHASHSEED=0``, the log given by a relative path so ``source`` does not name the
scratch folder) and hashes the JSON files. ``test_golden_outputs.py`` compares them with the
hashes stored in ``test/golden/diagnose_sha256.json``, recorded on the commit before the
redesign.

    python test/golden_outputs.py            # print the hashes as JSON
    python test/golden_outputs.py --write    # store them (only when a change is intended)
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from ads_rca.io.json_writer import write_run_log
from ads_rca.params import SEMANTICS
from ads_rca.synth import FAULTS, SCENARIOS, synthesise

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "examples" / "cut_in_perception"
STORED = Path(__file__).resolve().parent / "golden" / "diagnose_sha256.json"
SEED = 1
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


def digests() -> dict[str, str]:
    """``{"<log>/<semantics>": sha256 of its diagnose --json}`` for every log and mode."""
    env = {**os.environ, "PYTHONHASHSEED": "0"}
    out: dict[str, str] = {}
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
                out[f"{name}/{semantics}"] = hashlib.sha256(target.read_bytes()).hexdigest()
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help=f"store the hashes in {STORED}")
    args = parser.parse_args()
    text = json.dumps(digests(), indent=1, sort_keys=True) + "\n"
    if args.write:
        STORED.parent.mkdir(exist_ok=True)
        STORED.write_text(text)
    sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
