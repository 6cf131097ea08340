"""Test harness for ROS: every test gets its own DDS domain, local-only discovery, a log dir.

Domains: an explicitly set ``ROS_DOMAIN_ID`` (CI and the Makefile export one) is the base
of the domains handed out, else one derived from this process id. Each pytest-xdist worker
takes its own slice of ROS's safe range 1..101 starting at that base (the slices never
overlap), its first domain for this process and the next ones, in turn, for each test, so
no two workers and no two consecutive tests of one worker share a domain.

The variables are also set at import, before any test imports rclpy in this process, so
in-process ROS use obeys the network rule too. Each test additionally gets its own topic
namespace, so two suites running at once on this machine cannot mix their messages even
if their domain ids collide.

Markers: ``ros`` (the test starts ROS/DDS participants: every test using ``ros_env`` is
marked by :func:`pytest_collection_modifyitems`, the others in their modules) and ``slow``
(over about 5 s on a 2-core machine); ``pytest -m "not ros and not slow"`` is the fast
inner loop.
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

from ads_rca.errors import InputError
from ads_rca.ros.env import (
    MAX_DOMAIN_ID,
    pick_domain_id,
    requested_domain_id,
    ros_environment,
    use_node_profile,
)

#: The ROS_DOMAIN_ID the suite was started with, kept for the xdist workers (which inherit
#: this process's environment after the override below).
BASE_VARIABLE = "ADS_RCA_TEST_BASE_DOMAIN_ID"


def _base_domain_id() -> int:
    """The explicitly set ROS_DOMAIN_ID (0..232), else one derived from this process id."""
    if BASE_VARIABLE not in os.environ:
        os.environ[BASE_VARIABLE] = os.environ.get("ROS_DOMAIN_ID", "")
    try:
        requested = requested_domain_id(None, {"ROS_DOMAIN_ID": os.environ[BASE_VARIABLE]})
    except InputError as error:
        raise pytest.UsageError(str(error)) from error
    if requested is not None:
        return requested
    # Unset: one base for the whole run (xdist's workers share its id), else this process's.
    try:
        run: int | None = int(os.environ.get("PYTEST_XDIST_TESTRUNUID", ""), 16)
    except ValueError:
        run = None
    return pick_domain_id(run)


def worker_slice(base: int, worker: int, workers: int) -> list[int]:
    """The domains of ``worker`` (0-based) of ``workers``: disjoint slices of 1..MAX_DOMAIN_ID,
    worker 0's starting at ``base`` (moved into range), each worker's of equal size."""
    size = max(1, MAX_DOMAIN_ID // max(1, workers))
    start = (base - 1) % MAX_DOMAIN_ID + worker * size
    return [1 + (start + n) % MAX_DOMAIN_ID for n in range(size)]


def _this_worker() -> tuple[int, int]:
    """(index, count) of this pytest-xdist worker; (0, 1) without xdist."""
    name = os.environ.get("PYTEST_XDIST_WORKER", "")
    count = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1") or 1)
    index = int(name[2:]) if name.startswith("gw") and name[2:].isdigit() else 0
    return index % max(1, count), count


_DOMAINS = worker_slice(_base_domain_id(), *_this_worker())
#: This process's own domain first, then one per ``ros_env`` test in turn (never the first).
_NEXT = itertools.cycle(_DOMAINS[1:] or _DOMAINS)


def _domain_id() -> int:
    return next(_NEXT)


os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ["ROS_DOMAIN_ID"] = str(_DOMAINS[0])
os.environ.setdefault("ROS_LOG_DIR", tempfile.mkdtemp(prefix="ads_rca_test_ros_log_"))
# The participants tests create in this process get the nodes' Fast DDS profile too: UDP on
# loopback only, and writers that heartbeat every 1 ms while a sample is unacknowledged (by
# default every 3 s, so each ``wait_for_all_acked`` of a test's publisher took up to 3 s).
use_node_profile()
remove_zombie_segments()


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "ros: starts ROS/DDS participants (processes or rclpy)")
    config.addinivalue_line("markers", "slow: takes over about 5 s on a 2-core machine")


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Every test that takes ``ros_env`` starts ROS participants: mark it ``ros``. Then the
    files in order of their estimated cost, costliest first (a ``slow`` test as 10, a ``ros``
    test as 3, any other as 0.5): pytest-xdist, run with ``--dist loadfile
    --no-loadscope-reorder``, hands out whole files in this order, so no long file starts
    last while the other workers idle."""
    for item in items:
        if "ros_env" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.ros)
    cost: dict[Path, float] = {}
    for item in items:
        weight = (
            10 if item.get_closest_marker("slow") else 3 if item.get_closest_marker("ros") else 0.5
        )
        cost[item.path] = cost.get(item.path, 0.0) + weight
    items.sort(key=lambda item: -cost[item.path])


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


@pytest.fixture(scope="session")
def log_dirs(tmp_path_factory: pytest.TempPathFactory) -> Callable[[str, str], Path]:
    """Synthesised log folders by (scenario, fault), written once per session (per worker)."""
    from ads_rca.sources.log.writer import write_run_log

    def get(scenario: str, fault: str) -> Path:
        key = (scenario, fault)
        if key not in _LOG_DIRS:
            folder = tmp_path_factory.mktemp(f"{scenario}_{fault}")
            _LOG_DIRS[key] = write_run_log(synth(scenario, fault), folder / "log")
        return _LOG_DIRS[key]

    return get
