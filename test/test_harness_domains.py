"""The test harness's domains (test/conftest.py): an explicitly set ROS_DOMAIN_ID is the base,
every pytest-xdist worker takes a slice of 1..101 of its own, and a worker's tests take
turns through its slice."""

from __future__ import annotations

import os

import pytest
from conftest import BASE_VARIABLE, RosEnv, worker_slice

from ads_rca.ros.env import MAX_DOMAIN_ID


@pytest.mark.parametrize("base", [0, 1, 42, 77, 101, 102, 232])
@pytest.mark.parametrize("workers", [1, 2, 3, 4, 8])
def test_worker_slices_are_disjoint_in_range_and_start_at_the_base(base: int, workers: int) -> None:
    slices = [worker_slice(base, worker, workers) for worker in range(workers)]
    domains = [domain for one in slices for domain in one]
    assert len(domains) == len(set(domains)) == (MAX_DOMAIN_ID // workers) * workers
    assert all(1 <= domain <= MAX_DOMAIN_ID for domain in domains)
    if 1 <= base <= MAX_DOMAIN_ID:
        assert slices[0][0] == base  # the domain CI or the Makefile exported comes first
    assert len({len(one) for one in slices}) == 1


def test_each_test_runs_on_a_domain_of_its_workers_slice(ros_env: RosEnv) -> None:
    given = os.environ[BASE_VARIABLE]  # the ROS_DOMAIN_ID the suite was started with
    if given:
        worker = int(os.environ.get("PYTEST_XDIST_WORKER", "gw0")[2:])
        count = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
        assert ros_env.domain_id in worker_slice(int(given), worker, count)[1:]
    assert str(ros_env.domain_id) == os.environ["ROS_DOMAIN_ID"] == ros_env.env["ROS_DOMAIN_ID"]
    assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
