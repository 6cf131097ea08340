"""SUMO's own venv, its binaries and its pure-Python TraCI client.

SUMO is not our dependency: it lives in a venv of its own (``--venv``, default
``~/.cache/ads_rca/sumo-venv``), built here once from :data:`RECIPE` (``eclipse-sumo``
ships the ``sumo`` and ``netconvert`` binaries, ``traci`` and ``sumolib`` the pure-Python
client and network reader of the same release). Our interpreter reaches ``traci`` and
``sumolib`` by *appending* that venv's site-packages to ``sys.path`` at run time (appended,
so our numpy and everything else still come from our venv): both are pure Python of the
binaries' own release, so the TraCI protocol always matches the server. The simulator itself
always runs as a child process (``sumo`` over TraCI on a loopback socket, ``netconvert``
once per network): no compiled SUMO code is loaded into our process (``libsumo`` would be,
and would tie our interpreter to SUMO's build).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

SUMO_VERSION = "1.28.0"
RECIPE = (
    f"eclipse-sumo=={SUMO_VERSION}",
    f"traci=={SUMO_VERSION}",
    f"sumolib=={SUMO_VERSION}",
)
CACHE = Path.home() / ".cache" / "ads_rca"
DEFAULT_VENV = CACHE / "sumo-venv"
MARKER = "ads_rca-sumo-recipe.json"


@dataclass(frozen=True)
class Sumo:
    """Where SUMO is: its home (data files), binaries and the client's site-packages."""

    home: Path
    site_packages: Path
    version: str

    @property
    def sumo(self) -> Path:
        return self.home / "bin" / "sumo"

    @property
    def netconvert(self) -> Path:
        return self.home / "bin" / "netconvert"

    def environment(self) -> dict[str, str]:
        """The environment SUMO's binaries run in (``SUMO_HOME`` set)."""
        return {**os.environ, "SUMO_HOME": str(self.home)}


def ensure_sumo(venv: Path = DEFAULT_VENV, python: str = sys.executable) -> Sumo:
    """SUMO from ``venv``, the venv built first if missing or of another recipe."""
    wanted = {"recipe": list(RECIPE)}
    marker = venv / MARKER
    interpreter = venv / "bin" / "python"
    built = marker.exists() and json.loads(marker.read_text(encoding="utf-8")) == wanted
    if not (built and interpreter.exists()):
        print(f"building SUMO's venv in {venv} ...", flush=True)
        venv.parent.mkdir(parents=True, exist_ok=True)
        subprocess.run([python, "-m", "venv", "--clear", str(venv)], check=True)
        pip = [str(interpreter), "-m", "pip", "install", "--quiet", "--disable-pip-version-check"]
        subprocess.run([*pip, *RECIPE], check=True)
        marker.write_text(json.dumps(wanted), encoding="utf-8")
    found = sorted((venv / "lib").glob("python3*/site-packages"))
    if not found:
        raise SystemExit(f"{venv}: no site-packages")
    site = found[-1]
    return Sumo(home=site / "sumo", site_packages=site, version=SUMO_VERSION)


def client(sumo: Sumo) -> tuple[ModuleType, ModuleType]:
    """The ``traci`` and ``sumolib`` modules of SUMO's venv (pure Python)."""
    path = str(sumo.site_packages)
    if path not in sys.path:
        sys.path.append(path)
    os.environ.setdefault("SUMO_HOME", str(sumo.home))
    import sumolib  # type: ignore[import-not-found,unused-ignore]
    import traci  # type: ignore[import-not-found,unused-ignore]

    if not _CLIENT:
        _CLIENT.append((traci, sumolib))
    return traci, sumolib


_CLIENT: list[tuple[ModuleType, ModuleType]] = []


def client_modules() -> tuple[ModuleType, ModuleType]:
    """``traci`` and ``sumolib`` once :func:`client` has loaded them."""
    return _CLIENT[0]


def binary_version(sumo: Sumo) -> str:
    """``sumo --version``'s first line, e.g. ``Eclipse SUMO sumo 1.28.0``."""
    done = subprocess.run(
        [str(sumo.sumo), "--version"],
        capture_output=True,
        text=True,
        check=True,
        env=sumo.environment(),
    )
    return done.stdout.splitlines()[0].strip()
