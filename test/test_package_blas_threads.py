"""A process of ours runs numpy with one BLAS thread unless its user chose a number.

OpenBLAS starts a pool of threads when numpy loads; on arrays of a few dozen numbers they
never help, and their spinning cost a one-worker diagnose 9 % of its CPU time and a small
one 40 %. ``import ads_rca`` sets ``OPENBLAS_NUM_THREADS=1`` before any of its modules loads
numpy, and keeps a value the environment already gives. Counted as the operating system's
threads of a fresh interpreter (/proc/self/task)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

pytestmark = pytest.mark.skipif(not os.path.isdir("/proc/self/task"), reason="Linux only")

COUNT = (
    "import os, ads_rca.commands.diagnose_cmd, numpy; "
    "print(os.environ['OPENBLAS_NUM_THREADS'], len(os.listdir('/proc/self/task')))"
)


def threads(**env: str) -> tuple[str, int]:
    """The BLAS setting and the thread count of an interpreter that loaded diagnose."""
    environment = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    done = subprocess.run(
        [sys.executable, "-c", COUNT],
        env={**environment, **env},
        capture_output=True,
        text=True,
        check=True,
    )
    setting, count = done.stdout.split()
    return setting, int(count)


def test_numpy_loaded_by_ads_rca_starts_no_blas_threads() -> None:
    assert threads() == ("1", 1)


def test_a_number_the_user_set_is_kept() -> None:
    assert threads(OPENBLAS_NUM_THREADS="2") == ("2", 2)
