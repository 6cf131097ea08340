"""Runs the player and topic_summary as separate processes for the DDS tests."""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ads_rca.ros.launcher import Launcher, ParamValue, node_command

PLAYER = "ads_rca.ros.player"
SUMMARY = "ads_rca.ros.topic_summary"


@dataclass
class PairResult:
    player_code: int | None
    summary_code: int | None
    player_output: str
    summary_output: str
    summary: dict[str, Any]


def run_pair(
    env: dict[str, str],
    tmp: Path,
    player_params: dict[str, ParamValue],
    summary_params: dict[str, ParamValue] | None = None,
    player_params_file: Path | None = None,
    timeout: float = 40.0,
    player_executable: list[str] | None = None,
) -> PairResult:
    """Start topic_summary, then the player (waiting for it); wait for both to exit."""
    summary_file = tmp / "summary.json"
    summary_args: dict[str, ParamValue] = {"summary_file": str(summary_file), "timeout_s": 30.0}
    summary_args.update(summary_params or {})
    player_args: dict[str, ParamValue] = {"wait_for_subscribers": 1, "wait_timeout_s": 15.0}
    player_args.update(player_params)
    with Launcher(env, echo=sys.stderr) as launcher:
        summary = launcher.start("topic_summary", node_command(SUMMARY, summary_args))
        argv = node_command(PLAYER, player_args, player_params_file)
        if player_executable is not None:  # e.g. the colcon-installed lib/ads_rca/player
            argv = [*player_executable, *argv[3:]]
        player = launcher.start("player", argv)
        codes = {"player": player.wait(timeout)}
        if codes["player"] != 0:  # the subscriber would wait for its own timeout
            summary.stop(timeout=5.0)
        codes["topic_summary"] = summary.wait(timeout)
    document = json.loads(summary_file.read_text()) if summary_file.exists() else {}
    return PairResult(
        codes["player"], codes["topic_summary"], player.output, summary.output, document
    )


def wait_for(condition: Callable[[], Any], timeout: float, what: str) -> Any:
    """The first truthy ``condition()`` within ``timeout`` seconds, else AssertionError."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        found = condition()
        if found:
            return found
        time.sleep(0.05)
    raise AssertionError(f"timed out after {timeout} s waiting for {what}")
