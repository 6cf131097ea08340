"""Player and subscriber in separate processes over real DDS (local-only, own domain).

Each test starts ``topic_summary`` (the subscriber, rebuilding the log) and the ``player``
with the launcher, on the test's own ROS_DOMAIN_ID and topic namespace, and compares what
arrived with what was sent.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
from logcompare import assert_logs_equal
from logfactory import make_log
from rosrun import run_pair

from ads_rca.contract import topics
from ads_rca.ros.launcher import ManagedProcess, ParamValue, node_command
from ads_rca.sources.log.reader import read_run_log
from ads_rca.sources.log.writer import write_run_log

if TYPE_CHECKING:
    from conftest import RosEnv

pytestmark = pytest.mark.timeout(120)


@pytest.fixture
def log_dir(tmp_path: Path) -> Path:
    return write_run_log(make_log(24, 10, 11), tmp_path / "log")


def received(summary: dict[str, Any], namespace: str, key: str) -> int:
    return int(summary["topics"][topics.topic_name(key, namespace)]["received"])


@pytest.mark.parametrize("rate", [0.0, 20.0])
def test_whole_log_crosses_dds_unchanged(
    ros_env: RosEnv, tmp_path: Path, log_dir: Path, rate: float
) -> None:
    out = tmp_path / "rebuilt"
    ns = ros_env.namespace
    result = run_pair(
        ros_env.env,
        tmp_path,
        {"log_path": str(log_dir), "rate": rate, "topic_namespace": ns},
        {"topic_namespace": ns, "output_json": True, "output_dir": str(out)},
    )
    assert result.player_code == 0, result.player_output
    assert result.summary_code == 0, result.summary_output
    assert result.summary["complete"], result.summary
    original = read_run_log(log_dir)
    assert_logs_equal(original, read_run_log(out), angle_tol=1e-9)
    assert received(result.summary, ns, topics.FRAME) == len(original.frames)
    assert received(result.summary, ns, topics.CLOCK) == len(original.frames)
    assert result.summary["status"]["state"] == "finished"


def test_parameters_on_the_command_line_select_frames(
    ros_env: RosEnv, tmp_path: Path, log_dir: Path
) -> None:
    ns = ros_env.namespace
    result = run_pair(
        ros_env.env,
        tmp_path,
        {
            "log_path": str(log_dir),
            "rate": 0,
            "topic_namespace": ns,
            "start_frame": 5,
            "stop_frame": 9,
            "publish_clock": False,
        },
        {"topic_namespace": ns, "output_json": True, "output_dir": str(tmp_path / "out")},
    )
    assert result.player_code == 0 and result.summary_code == 0, result.player_output
    original = read_run_log(log_dir)
    rebuilt = read_run_log(tmp_path / "out")
    assert rebuilt.frames == original.frames[5:10]
    assert received(result.summary, ns, topics.CLOCK) == 0
    assert result.summary["status"]["frames_published"] == 5


def test_params_file_sets_namespace_range_and_rate(
    ros_env: RosEnv, tmp_path: Path, log_dir: Path
) -> None:
    ns = ros_env.namespace + "_from_file"
    params = tmp_path / "player.yaml"
    params.write_text(
        "/**:\n  ros__parameters:\n"
        f"    log_path: {log_dir}\n    topic_namespace: {ns}\n"
        "    start_frame: 2\n    stop_frame: 11\n    rate: 0.5\n"
    )
    result = run_pair(ros_env.env, tmp_path, {}, {"topic_namespace": ns}, player_params_file=params)
    assert result.player_code == 0 and result.summary_code == 0, result.player_output
    assert received(result.summary, ns, topics.FRAME) == 10
    # 10 frames 50 ms apart at rate 0.5: the last one is due 9 * 50 ms / 0.5 after the first.
    paced = result.summary["status"]["elapsed_s"]
    assert paced >= 0.9
    fast = run_pair(
        ros_env.env,
        tmp_path,
        {"rate": 0.0},
        {"topic_namespace": ns},
        player_params_file=params,
    )
    assert fast.player_code == 0 and fast.summary_code == 0, fast.player_output
    assert received(fast.summary, ns, topics.FRAME) == 10
    assert fast.summary["status"]["elapsed_s"] < 0.6 < paced  # -p rate:=0.0 beat the file


@pytest.mark.parametrize(
    "params",
    [{"log_path": "/nonexistent/ads_rca_log"}, {}, {"log_path": "/tmp", "rate": -1.0}],
    ids=["missing-folder", "no-log-path", "negative-rate"],
)
def test_bad_input_is_one_line_and_exit_status_2(
    ros_env: RosEnv, params: dict[str, ParamValue]
) -> None:
    player = ManagedProcess("player", node_command("ads_rca.ros.player", params), ros_env.env)
    assert player.wait(30) == 2
    lines = [line for line in player.output.splitlines() if line.strip()]
    assert "Traceback" not in player.output
    assert len(lines) == 1 and "ERROR" in lines[0] and "player" in lines[0], player.output


def test_demo_command_plays_a_log_and_rebuilds_it(
    ros_env: RosEnv, tmp_path: Path, log_dir: Path
) -> None:
    out = tmp_path / "demo_out"
    argv = [sys.executable, "-m", "ads_rca.cli", "demo", str(log_dir), "--out", str(out)]
    argv += ["--domain-id", str(ros_env.domain_id)]
    demo = ManagedProcess("demo", argv, ros_env.env)
    assert demo.wait(90) == 0, demo.output
    assert "[topic_summary]" in demo.output and "complete" in demo.output
    assert_logs_equal(read_run_log(log_dir), read_run_log(out / "rebuilt_log"))
    missing = ManagedProcess(
        "demo", [sys.executable, "-m", "ads_rca.cli", "demo", str(tmp_path / "nope")], ros_env.env
    )
    assert missing.wait(30) == 2
    assert "Traceback" not in missing.output and "no such log folder" in missing.output
