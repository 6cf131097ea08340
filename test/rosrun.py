"""Starting the package's nodes and the tests' probe processes for the DDS tests, and
reading what they write."""

from __future__ import annotations

import contextlib
import json
import sys
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ads_rca.contract import topics
from ads_rca.ros.launcher import Launcher, ManagedProcess, ParamValue, node_command
from ads_rca.sources.bag.reader import iter_mcap_stream

if TYPE_CHECKING:
    from conftest import RosEnv

PLAYER = "ads_rca.ros.player"
#: Prints every /diagnostics status it hears as a JSON line (:func:`start_probe`).
PROBE = Path(__file__).parent / "diag_probe.py"
#: A Zenoh session with no rclpy that writes what it receives as JSON lines (:func:`listener`).
LISTENER = Path(__file__).parent / "zenoh_listener.py"
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


def start_node(launcher: Launcher, name: str, module: str, params: dict[str, ParamValue]) -> Any:
    return launcher.start(name, node_command(module, params))


def start_recorder(launcher: Launcher, bag: Path, ns: str, **extra: ParamValue) -> Any:
    """The recorder writing ``bag``, listening under namespace ``ns``."""
    params: dict[str, ParamValue] = {"output": str(bag), "topic_namespace": ns, **extra}
    return start_node(launcher, "recorder", "ads_rca.ros.recorder", params)


def start_player(launcher: Launcher, log_dir: Path, ns: str, **extra: ParamValue) -> Any:
    """The player at rate 0, waiting for the recorder to subscribe first."""
    params: dict[str, ParamValue] = {
        "log_path": str(log_dir),
        "rate": 0.0,
        "topic_namespace": ns,
        "wait_for_subscribers": 1,
        "wait_timeout_s": 15.0,
        **extra,
    }
    return start_node(launcher, "player", "ads_rca.ros.player", params)


def recorded_counts(bag: Path, ns: str) -> Counter[str]:
    keys = {name: key for key, name in topics.topic_names(ns).items()}
    return Counter(keys[m.topic] for m in iter_mcap_stream(next(bag.glob("*.mcap"))))


def jsonl(path: Path) -> list[dict[str, Any]]:
    if not path.exists():
        return []
    rows = []
    for line in path.read_text().splitlines():
        with contextlib.suppress(ValueError):  # a line being written
            rows.append(json.loads(line))
    return rows


def start_probe(ros_env: RosEnv, path: Path) -> ManagedProcess:
    probe = ManagedProcess("probe", [sys.executable, str(PROBE), str(path)], ros_env.env)
    wait_for(lambda: "probe ready" in probe.output, 20, "the probe")
    return probe


def rows(path: Path) -> list[dict[str, Any]]:
    """The listener's lines so far (none before it opened its file; not a half-written one)."""
    if not path.exists():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.endswith("}")]


def listener(env: dict[str, str], out: Path, *options: str) -> ManagedProcess:
    argv = [sys.executable, str(LISTENER), str(out), *options]
    return ManagedProcess(out.stem, argv, env)
