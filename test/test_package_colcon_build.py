"""The package builds with colcon like any ROS 2 ament_python package, and runs from there.

Builds into a temp workspace with the venv's colcon, checks the ament layout, then finds the
installed ``player`` exactly as ``ros2 run ads_rca player`` does (ament index under
AMENT_PREFIX_PATH) and checks that it publishes a log to a subscriber over DDS.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

import pytest
from colconbuild import REPO, build_workspace, colcon
from logfactory import make_log
from rosrun import run_pair

from ads_rca.contract import topics
from ads_rca.sources.log.writer import write_run_log

if TYPE_CHECKING:
    from conftest import RosEnv


# colcon is pinned in requirements-dev.txt: a missing colcon is a failure, not a skip.
pytestmark = pytest.mark.timeout(180)


@pytest.fixture(scope="module")
def install(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_workspace(tmp_path_factory.mktemp("colcon_ws"))


def test_colcon_sees_an_ament_python_package(tmp_path: Path) -> None:
    listing = colcon(tmp_path, "list", "--base-paths", str(REPO))
    assert any(
        line.split()[0] == "ads_rca" and "(ros.ament_python)" in line
        for line in listing.splitlines()
    ), listing


def test_installed_layout_is_what_ros2_run_expects(install: Path) -> None:
    prefix = install / "ads_rca"
    nodes = ("player", "topic_summary", "recorder", "aggregator", "monitors")
    monitors = (
        "perception_monitor",
        "prediction_monitor",
        "planning_monitor",
        "controller_monitor",
    )
    for exe in (*nodes, *monitors):
        assert os.access(prefix / "lib" / "ads_rca" / exe, os.X_OK), exe
    assert (prefix / "share/ament_index/resource_index/packages/ads_rca").is_file()
    assert (prefix / "share/ads_rca/package.xml").is_file()
    assert (prefix / "share/ads_rca/config/player.yaml").is_file()
    assert (prefix / "share/ads_rca/launch_scripts/player.launch.py").is_file()
    site = next((prefix / "lib").glob("python3*/site-packages"))
    for page in ("index.html", "app.js", "app.css"):  # ads-rca dashboard's page
        assert (site / "ads_rca/remote/static" / page).is_file(), page


def test_installed_player_found_via_ament_index_publishes(
    install: Path, ros_env: RosEnv, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from ament_index_python.packages import get_package_prefix

    site = next((install / "ads_rca" / "lib").glob("python3*/site-packages"))
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(install / "ads_rca"))
    prefix = Path(get_package_prefix("ads_rca"))
    assert prefix == install / "ads_rca"
    player = prefix / "lib" / "ads_rca" / "player"
    env = dict(ros_env.env, AMENT_PREFIX_PATH=str(prefix), PYTHONPATH=str(site))
    log_dir = write_run_log(make_log(6, 4, 5), tmp_path / "log")
    ns = ros_env.namespace
    result = run_pair(
        env,
        tmp_path,
        {"log_path": str(log_dir), "rate": 0.0, "topic_namespace": ns},
        {"topic_namespace": ns},
        player_executable=[str(player)],
    )
    assert result.player_code == 0, result.player_output
    assert result.summary_code == 0 and result.summary["complete"], result.summary_output
    frames = result.summary["topics"][topics.topic_name(topics.FRAME, ns)]["received"]
    assert frames == 6


def test_installed_stack_mode_with_the_stack_file_gives_the_verdict(
    install: Path, ros_env: RosEnv, tmp_path: Path
) -> None:
    """``ros2 run ads_rca monitors`` / ``aggregator`` from the workspace with the installed
    ``config/stack_contract.yaml``, beside a stack: the verdict is ``diagnose``'s."""
    from stackgraph import run_stack_graph

    from ads_rca.diagnosis.engine import diagnose
    from ads_rca.params import make_params
    from ads_rca.synth import synthesise

    prefix = install / "ads_rca"
    site = next((prefix / "lib").glob("python3*/site-packages"))
    env = dict(ros_env.env, AMENT_PREFIX_PATH=str(prefix), PYTHONPATH=str(site))
    stack_file = prefix / "share/ads_rca/config/stack_contract.yaml"
    run = run_stack_graph(
        env,
        tmp_path,
        "lead_braking:planning:1",
        {"semantics": "corrected", "input_timeout_s": 30.0},  # no loss: never waited on
        ["--namespace", "/ads_rca", "--seed", "2"],  # the stack file's topics
        params_file=stack_file,
        executables={
            name: [str(prefix / "lib/ads_rca" / name)] for name in ("monitors", "aggregator")
        },
    )
    [verdict] = run.verdicts
    expected = diagnose(synthesise("lead_braking", "planning", 1), make_params("corrected"))
    want = expected.to_json()
    for key in ("primary_root_cause", "root_causes", "contributing", "partner_id"):
        assert verdict[key] == want[key]
    assert verdict["live"]["complete"] is True
    assert "stack mode: frames from /ads_rca/ego/odometry stamps" in run.outputs["monitors"]
