"""The live node graph as separate processes: player, monitors, aggregator, recorder.

The pure-Python counterpart of ``launch_scripts/rca_graph.launch.py`` (``launch`` is not
installed here), used by ``ads-rca replay``, the tests and the benchmark. Every node is its
own ``python -m`` process in the launcher's environment (local-only discovery, the caller's
domain). Start order: recorder, aggregator, monitors, then the player, which waits until
all of them subscribe to ``run/frame`` so none misses the first frame. The verdict is read
from the aggregator's ``verdict_json`` file (written atomically once it is published).

The four monitors run either as one ``monitors`` process (``MONITORS_SHARED``, the default:
inputs received and decoded once) or as four processes (``MONITORS_SEPARATE``: one monitor
can be killed and restarted on its own).
"""

from __future__ import annotations

import importlib.util
import json
import sys
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

from ads_rca.live.runid import new_run_id
from ads_rca.params import Params
from ads_rca.ros.launcher import Launcher, ManagedProcess, ParamValue, ros_args
from ads_rca.ros.monitor import GROUP, MONITORS
from ads_rca.ros.nodeparams import engine_values

PLAYER = "ads_rca.ros.player"
AGGREGATOR = "ads_rca.ros.aggregator"
MONITOR = "ads_rca.ros.monitor"
RECORDER = "ads_rca.ros.recorder"
MONITORS_SHARED = "shared"
MONITORS_SEPARATE = "separate"
MONITOR_LAYOUTS = (MONITORS_SHARED, MONITORS_SEPARATE)


def recorder_available() -> bool:
    """The recorder node exists in this installation."""
    return importlib.util.find_spec(RECORDER) is not None


@dataclass
class GraphSpec:
    """What to run: the log, the engine parameters and per-node extras."""

    log_path: Path
    params: Params
    verdict_json: Path
    namespace: str = "/ads_rca"
    rate: float = 0.0
    record: Path | None = None
    metrics_log: Path | None = None
    monitor_params: dict[str, ParamValue] = field(default_factory=dict)
    aggregator_params: dict[str, ParamValue] = field(default_factory=dict)
    player_params: dict[str, ParamValue] = field(default_factory=dict)
    monitors: str = MONITORS_SHARED
    #: Every node of the graph is given this run id, so it ignores any other run that
    #: shares its domain and namespace (see ads_rca.live.runid).
    run_id: str = field(default_factory=new_run_id)

    def __post_init__(self) -> None:
        if self.monitors not in MONITOR_LAYOUTS:
            raise ValueError(f"monitors must be one of {MONITOR_LAYOUTS}, not {self.monitors!r}")

    def common(self) -> dict[str, ParamValue]:
        return {
            **engine_values(self.params),
            "topic_namespace": self.namespace,
            "run_id": self.run_id,
        }

    def monitor_argv(self, node_name: str) -> list[str]:
        params = {**self.common(), **self.monitor_params}
        return [sys.executable, "-m", MONITOR, node_name, *ros_args(params)]

    def commands(self) -> dict[str, list[str]]:
        """Node name → argv, in start order."""
        out: dict[str, list[str]] = {}
        if self.record is not None:
            rec: dict[str, ParamValue] = {
                "output": str(self.record),
                "topic_namespace": self.namespace,
                "run_id": self.run_id,
            }
            out["recorder"] = [sys.executable, "-m", RECORDER, *ros_args(rec)]
        agg: dict[str, ParamValue] = {
            **self.common(),
            "verdict_json": str(self.verdict_json),
            **({"metrics_log": str(self.metrics_log)} if self.metrics_log else {}),
            **self.aggregator_params,
        }
        out["aggregator"] = [sys.executable, "-m", AGGREGATOR, *ros_args(agg)]
        names = MONITORS if self.monitors == MONITORS_SEPARATE else (GROUP,)
        for name in names:
            out[name] = self.monitor_argv(name)
        player: dict[str, ParamValue] = {
            "log_path": str(self.log_path),
            "rate": float(self.rate),
            "topic_namespace": self.namespace,
            "run_id": self.run_id,
            "wait_for_subscribers": len(out),  # every node subscribes to run/frame
            "wait_timeout_s": 30.0,
            **self.player_params,
        }
        out["player"] = [sys.executable, "-m", PLAYER, *ros_args(player)]
        return out


class Graph:
    """A running graph; use as a context manager (everything stops on exit)."""

    def __init__(self, spec: GraphSpec, env: Mapping[str, str], echo: TextIO | None = None) -> None:
        self.spec = spec
        self.launcher = Launcher(env, echo=echo)
        self.started_at = 0.0

    def start(self, skip: tuple[str, ...] = ()) -> None:
        self.spec.verdict_json.unlink(missing_ok=True)
        self.started_at = time.monotonic()
        for name, argv in self.spec.commands().items():
            if name not in skip:
                self.launcher.start(name, argv)

    @property
    def processes(self) -> dict[str, ManagedProcess]:
        return self.launcher.processes

    def restart(self, name: str) -> ManagedProcess:
        """Start node ``name`` again (after it was stopped or killed)."""
        return self.launcher.start(name, self.spec.commands()[name])

    def verdict(self) -> dict[str, Any] | None:
        """The verdict document once the aggregator wrote it."""
        try:
            document = json.loads(self.spec.verdict_json.read_text())
        except (OSError, ValueError):
            return None
        return document if isinstance(document, dict) else None

    def wait_verdict(self, timeout: float, fail_fast: bool = True) -> dict[str, Any] | None:
        """Poll for the verdict; None on timeout, when the aggregator died, or (``fail_fast``)
        as soon as any node failed (see :meth:`failed`)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            found = self.verdict()
            if found is not None:
                return found
            aggregator = self.processes.get("aggregator")
            if aggregator is not None and aggregator.returncode is not None:
                return self.verdict()
            if fail_fast and self.failed():
                return self.verdict()
            time.sleep(0.05)
        return None

    def failed(self) -> dict[str, int]:
        """Nodes that exited before the verdict, with their status.

        Every node but the player runs until stopped; the player exits 0 after playing
        (``exit_on_end``), so only a non-zero player status counts (2: unusable input,
        negative: killed by that signal).
        """
        return {
            name: code
            for name, p in self.processes.items()
            if (code := p.returncode) is not None and (name != "player" or code != 0)
        }

    def stop(self, player_grace_s: float = 10.0) -> dict[str, int]:
        """Let the player finish (it exits after its acks), then stop the rest in reverse."""
        player = self.processes.get("player")
        if player is not None:
            player.wait(player_grace_s)
        return self.launcher.stop_all()

    def __enter__(self) -> Graph:
        return self

    def __exit__(self, *exc: object) -> None:
        self.launcher.stop_all()
