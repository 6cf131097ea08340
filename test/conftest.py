"""Test harness for ROS: every test gets its own DDS domain, local-only discovery, a log dir.

The variables are also set at import, before any test imports rclpy in this process, so
in-process ROS use obeys the network rule too. Each test additionally gets its own topic
namespace, so two suites running at once on this machine cannot mix their messages even
if their domain ids collide.
"""

from __future__ import annotations

import itertools
import os
import sys
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))

from shmclean import remove_zombie_segments
from synthlogs import synth

from ads_rca.ros.env import MAX_DOMAIN_ID, ros_environment

_COUNTER = itertools.count(1)


def _domain_id() -> int:
    return 1 + (os.getpid() * 7 + next(_COUNTER)) % MAX_DOMAIN_ID


os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ["ROS_DOMAIN_ID"] = str(_domain_id())
os.environ.setdefault("ROS_LOG_DIR", tempfile.mkdtemp(prefix="ads_rca_test_ros_log_"))
remove_zombie_segments()


@dataclass(frozen=True)
class RosEnv:
    """What a test needs to start ROS processes in isolation."""

    domain_id: int
    log_dir: Path
    namespace: str
    env: dict[str, str]


@pytest.fixture
def ros_env(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[RosEnv]:
    domain_id = _domain_id()
    log_dir = tmp_path / "ros_log"
    log_dir.mkdir()
    env = ros_environment(domain_id=domain_id, log_dir=log_dir)
    for key in ("ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_DOMAIN_ID", "ROS_LOG_DIR"):
        monkeypatch.setenv(key, env[key])
    namespace = f"/ads_rca_test_{os.getpid()}_{domain_id}"
    yield RosEnv(domain_id, log_dir, namespace, env)
    # Nodes a test killed leave their shared memory behind; see shmclean.
    remove_zombie_segments()


_LOG_DIRS: dict[tuple[str, str], Path] = {}


@pytest.fixture(scope="module")
def log_dirs(tmp_path_factory: pytest.TempPathFactory) -> Callable[[str, str], Path]:
    """Synthesised log folders by (scenario, fault), written once per session."""
    from ads_rca.sources.log.writer import write_run_log

    def get(scenario: str, fault: str) -> Path:
        key = (scenario, fault)
        if key not in _LOG_DIRS:
            folder = tmp_path_factory.mktemp(f"{scenario}_{fault}")
            _LOG_DIRS[key] = write_run_log(synth(scenario, fault), folder / "log")
        return _LOG_DIRS[key]

    return get
