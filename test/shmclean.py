"""Removes the shared-memory files of Fast DDS participants that died without closing them.

Why: a test that SIGKILLs a node (on purpose) leaves its port and segment files in
/dev/shm. Fast DDS reopens such a "zombie" port when a later participant gets the same port
number, and that path can crash the new process (SIGSEGV in create_participant,
eProsima/Fast-DDS#6501, reported on 3.6.1; the wheels carry 3.2.3). Removing zombies
between tests means no process ever reopens one.

A file is a zombie when its ``_el`` lock file is not locked: a live participant holds an
exclusive ``flock`` on it for as long as the segment is open (the rule Fast DDS's own
``fastdds shm clean`` applies). Files of live participants are never touched, nor files
younger than ``min_age_s``: a participant starting in another test process (pytest-xdist
workers run side by side) creates its lock file an instant before it locks it.
"""

from __future__ import annotations

import fcntl
import os
import re
import time
from pathlib import Path

SHM_DIR = Path("/dev/shm")
#: ``fastdds_<16 hex>_el`` (a participant's data segment) or ``fastdds_port<N>_el`` (a
#: listening port); Fast DDS 2 used the prefix ``fastrtps_``.
_LOCK = re.compile(r"^(fastdds|fastrtps)_([0-9a-f]{16}|port\d{1,5})_(el|sl)$")


def _locked(path: Path) -> bool:
    try:
        with open(path, "ab") as handle:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        return True
    return False


def _younger_than(path: Path, seconds: float) -> bool:
    try:
        return time.time() - path.stat().st_mtime < seconds
    except OSError:
        return True


def remove_zombie_segments(shm_dir: Path = SHM_DIR, min_age_s: float = 2.0) -> list[str]:
    """Delete every unlocked Fast DDS segment/port with its lock and mutex, unless its lock
    file is younger than ``min_age_s``; names removed."""
    try:
        names = os.listdir(shm_dir)
    except OSError:
        return []
    removed = []
    for name in names:
        if not _LOCK.match(name) or _younger_than(shm_dir / name, min_age_s):
            continue
        if _locked(shm_dir / name):
            continue
        base = name[:-3]
        for victim in (base, name, f"sem.{base}_mutex"):
            try:
                os.remove(shm_dir / victim)
                removed.append(victim)
            except OSError:
                pass
    return removed
