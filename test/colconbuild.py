"""Building this package with colcon in a temp workspace, as a ROS user does."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
COLCON = Path(sys.executable).parent / "colcon"


def colcon(workspace: Path, *args: str) -> str:
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1")
    result = subprocess.run(
        [str(COLCON), "--log-base", str(workspace / "log"), *args],
        cwd=workspace,
        env=env,
        capture_output=True,
        text=True,
        timeout=150,
        check=False,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    return result.stdout


def build_workspace(workspace: Path) -> Path:
    """``colcon build`` of this package in ``workspace``, as a user does; the install base."""
    colcon(
        workspace,
        "build",
        "--base-paths", str(REPO),
        "--packages-select", "ads_rca",
        "--build-base", str(workspace / "build"),
        "--install-base", str(workspace / "install"),
        "--executor", "sequential",
    )  # fmt: skip
    return workspace / "install"
