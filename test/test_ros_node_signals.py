"""SIGINT/SIGTERM to a whole process group of real nodes: every node exits 0.

A terminal's Ctrl-C reaches every process of the foreground group at once, and ``ros2
launch`` runs its nodes in its own group. The graph's nodes (player, monitors, aggregator,
recorder) are started by a leader in one fresh process group (``pgroup.py``); once every
monitor and the aggregator have handled the run's first message (each monitor says "judging
run", the aggregator its frame period: their executors are spinning), the signal goes to the
group, mid-run. Each node must stop spinning, close, destroy its node, shut
rclpy down and exit 0, with no C++ abort ("terminate called ... error_already_set") and no
traceback, in both monitor layouts.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import pytest
from rosrun import wait_for

from ads_rca.params import make_params
from ads_rca.ros.graph import MONITORS_SEPARATE, MONITORS_SHARED, GraphSpec

if TYPE_CHECKING:
    from conftest import RosEnv

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "cut_in_perception"
LEADER = Path(__file__).resolve().parent / "pgroup.py"
pytestmark = pytest.mark.timeout(180)


def said(out: Path, name: str, text: str) -> bool:
    """Whether node ``name`` has written ``text`` to its output file so far."""
    try:
        return text in (out / f"{name}.out").read_text()
    except OSError:
        return False


@pytest.mark.slow
@pytest.mark.parametrize("layout", [MONITORS_SHARED, MONITORS_SEPARATE])
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_group_signal_stops_every_node_cleanly(
    layout: str, sig: signal.Signals, ros_env: RosEnv, tmp_path: Path
) -> None:
    metrics = tmp_path / "metrics.jsonl"
    spec = GraphSpec(
        log_path=EXAMPLE,
        params=make_params("corrected"),
        verdict_json=tmp_path / "verdict.json",
        namespace=ros_env.namespace,
        rate=0.5,  # about 8 s of playing: the signal comes mid-run
        record=tmp_path / "bag",
        metrics_log=metrics,
        monitors=layout,
    )
    commands = spec.commands()
    (tmp_path / "spec.json").write_text(json.dumps({"out": str(tmp_path), "commands": commands}))
    leader = subprocess.Popen(
        [sys.executable, str(LEADER), str(tmp_path / "spec.json")],
        env=ros_env.env,
        start_new_session=True,
    )
    try:
        # Not the results: in corrected mode the example's results all come at its collision,
        # its last frame, a moment before the verdict, so a signal sent on them could come
        # after the verdict on a loaded machine.
        monitors = [name for name in commands if "monitor" in name]
        wait_for(
            lambda: (
                all(said(tmp_path, name, "judging run") for name in monitors)
                and said(tmp_path, "aggregator", " ms per frame, ")
            ),
            90.0,
            "every monitor and the aggregator handling the run",
        )
        assert leader.poll() is None
        os.killpg(leader.pid, sig)
        assert leader.wait(60.0) == 0
    finally:
        if leader.poll() is None:
            os.killpg(leader.pid, signal.SIGKILL)
            leader.wait()
    codes = json.loads((tmp_path / "codes.json").read_text())
    assert set(codes) == set(commands)
    outputs = {name: (tmp_path / f"{name}.out").read_text() for name in commands}
    for name, text in outputs.items():
        assert "terminate called" not in text, f"{name}:\n{text}"
        assert "Traceback" not in text, f"{name}:\n{text}"
    assert codes == dict.fromkeys(commands, 0), outputs
    assert not (tmp_path / "verdict.json").exists()  # stopped mid-run, before the verdict
    assert (tmp_path / "bag" / "metadata.yaml").is_file()  # the recorder finalised its bag
