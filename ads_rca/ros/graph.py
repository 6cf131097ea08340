"""The live node graph, described once: which nodes, with which parameters, and when it ends.

:class:`GraphSpec` lists the graph's nodes (:class:`NodeSpec`: the ``ros2 run`` executable,
the ``python -m`` module, the parameters). Two things start it from that one description:
``ads-rca replay`` (and the tests and the benchmark), through :class:`Graph`, each node its
own ``python -m`` process in the launcher's environment (local-only discovery, the caller's
domain); and ``launch_scripts/rca_graph.launch.py``, whose arguments are
:data:`LAUNCH_ARGUMENTS` (replay's options under their launch names, turned into a spec by
:func:`spec_from_arguments`) and whose exit handlers follow :func:`exit_outcome`. Start
order: recorder, aggregator, monitors, then the player, which waits until all of them
subscribe to ``run/frame`` so none misses the first frame (the recorder and the bridge say
they are ready only once they matched the monitors' and the aggregator's outputs, so a short
run's results cannot be over before they hear them). ``replay`` reads the verdict
from the aggregator's ``verdict_json`` file (written atomically once it is published).

The four monitors run either as one ``monitors`` process (``MONITORS_SHARED``, the default:
inputs received and decoded once) or as four processes (``MONITORS_SEPARATE``: one monitor
can be killed and restarted on its own).
"""

from __future__ import annotations

import importlib.util
import json
import signal
import sys
import time
from collections.abc import Collection, Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, TextIO

from ads_rca.contract import topics
from ads_rca.errors import InputError
from ads_rca.foundation.files import DEFAULT_MAX_FILE_MB
from ads_rca.foundation.yaml_files import load_config
from ads_rca.live.runid import new_run_id
from ads_rca.oracles.base import MODULES, Module
from ads_rca.oracles.semantics import EVENT_PARAMETERS
from ads_rca.params import SEMANTICS, Params, params_from_sources
from ads_rca.paramspec import LINGER, MAX_FILE_MB, RATE, check_number
from ads_rca.ros.launcher import Launcher, ManagedProcess, ParamValue, ros_args
from ads_rca.sources.bag.profiles import BUILTIN_PROFILES
from ads_rca.sources.formats import AUTO, SOURCE_PARAMS, SourceOptions
from ads_rca.sources.registry import FORMATS

PLAYER = "ads_rca.ros.player"
AGGREGATOR = "ads_rca.ros.aggregator"
MONITOR = "ads_rca.ros.monitor"
RECORDER = "ads_rca.ros.recorder"
BRIDGE = "ads_rca.ros.zenoh_bridge"
#: Monitor node name → module it judges: ``<module>_monitor``, in pipeline order.
MONITORS: dict[str, Module] = {f"{module}_monitor": module for module in MODULES}
#: The bridge's node, process and executable name.
BRIDGE_NAME = "zenoh_bridge"
#: What the bridge logs once it forwarded the verdict: ``replay`` stops the rest of the
#: graph only then (nothing the bridge still had to hear is lost), the bridge lingering on.
BRIDGE_FORWARDED = "verdict forwarded"
#: The executable that runs all four monitors in one process.
GROUP = "monitors"
MONITORS_SHARED = "shared"
MONITORS_SEPARATE = "separate"
MONITOR_LAYOUTS = (MONITORS_SHARED, MONITORS_SEPARATE)
#: How long the player waits for every node to be ready before playing anyway.
PLAYER_WAIT_S = 30.0
#: How long the recorder and the bridge wait to match the monitors' and the aggregator's
#: outputs before they say they are ready (inside the player's wait, which started later).
GRAPH_WAIT_S = 20.0


def recorder_available() -> bool:
    """The recorder node exists in this installation."""
    return importlib.util.find_spec(RECORDER) is not None


@dataclass(frozen=True)
class NodeSpec:
    """One process of the graph."""

    #: Its name in the graph (``replay``'s messages, the launcher's process table).
    name: str
    #: The executable ``ros2 run ads_rca <executable>`` starts (setup.py's console scripts).
    executable: str
    #: The module ``python -m`` runs, and its first argument (the monitor node's name).
    module: str
    module_argument: str | None
    params: dict[str, ParamValue]

    def argv(self) -> list[str]:
        """``python -m module [argument] --ros-args -p ...`` with our interpreter."""
        first = [self.module_argument] if self.module_argument else []
        return [sys.executable, "-m", self.module, *first, *ros_args(self.params)]


@dataclass
class GraphSpec:
    """What to run: the log, the engine parameters and per-node extras."""

    log_path: Path
    params: Params
    verdict_json: Path | None
    namespace: str = topics.DEFAULT_NAMESPACE
    rate: float = 0.0
    record: Path | None = None
    metrics_log: Path | None = None
    monitor_params: dict[str, ParamValue] = field(default_factory=dict)
    aggregator_params: dict[str, ParamValue] = field(default_factory=dict)
    player_params: dict[str, ParamValue] = field(default_factory=dict)
    monitors: str = MONITORS_SHARED
    #: The aggregator exits 0 once its verdict is acknowledged (the launch file's end of run).
    exit_after_verdict: bool = False
    #: The Zenoh bridge's own parameters (None: no bridge). It forwards this run only and
    #: exits once its verdict is out and its ``linger_s`` passed.
    zenoh_params: dict[str, ParamValue] | None = None
    #: Every node of the graph is given this run id, so it ignores any other run that
    #: shares its domain and namespace (see ads_rca.live.runid).
    run_id: str = field(default_factory=new_run_id)

    def __post_init__(self) -> None:
        if self.monitors not in MONITOR_LAYOUTS:
            raise ValueError(f"monitors must be one of {MONITOR_LAYOUTS}, not {self.monitors!r}")

    def common(self) -> dict[str, ParamValue]:
        return {
            **asdict(self.params),  # every engine parameter, semantics included
            "topic_namespace": self.namespace,
            "run_id": self.run_id,
        }

    def nodes(self) -> list[NodeSpec]:
        """Every node, in start order."""
        out: list[NodeSpec] = []
        if self.record is not None:
            rec: dict[str, ParamValue] = {
                "output": str(self.record),
                "topic_namespace": self.namespace,
                "run_id": self.run_id,
                "graph_wait_s": GRAPH_WAIT_S,
            }
            out.append(NodeSpec("recorder", "recorder", RECORDER, None, rec))
        if self.zenoh_params is not None:
            bridge: dict[str, ParamValue] = {
                "topic_namespace": self.namespace,
                "run_id": self.run_id,
                "exit_after_verdict": True,
                "graph_wait_s": GRAPH_WAIT_S,
                **self.zenoh_params,
            }
            out.append(NodeSpec(BRIDGE_NAME, BRIDGE_NAME, BRIDGE, None, bridge))
        agg: dict[str, ParamValue] = {
            **self.common(),
            **({"verdict_json": str(self.verdict_json)} if self.verdict_json else {}),
            **({"metrics_log": str(self.metrics_log)} if self.metrics_log else {}),
            **({"exit_after_verdict": True} if self.exit_after_verdict else {}),
            **self.aggregator_params,
        }
        out.append(NodeSpec("aggregator", "aggregator", AGGREGATOR, None, agg))
        names = MONITORS if self.monitors == MONITORS_SEPARATE else (GROUP,)
        for name in names:
            params = {**self.common(), **self.monitor_params}
            out.append(NodeSpec(name, name, MONITOR, name, params))
        player: dict[str, ParamValue] = {
            "log_path": str(self.log_path),
            "rate": float(self.rate),
            "topic_namespace": self.namespace,
            "run_id": self.run_id,
            "wait_for_subscribers": len(out),  # every node subscribes to run/frame
            "wait_timeout_s": PLAYER_WAIT_S,
            # The run is played as the engine judges it: its critical event by these.
            **{name: float(getattr(self.params, name)) for name in EVENT_PARAMETERS},
            **self.player_params,
        }
        out.append(NodeSpec("player", "player", PLAYER, None, player))
        return out

    @property
    def last_node(self) -> str:
        """The node whose exit 0 ends the run: the bridge once it forwarded the verdict and
        lingered, else the aggregator once its verdict was acknowledged."""
        return BRIDGE_NAME if self.zenoh_params is not None else "aggregator"

    def commands(self) -> dict[str, list[str]]:
        """Node name → argv, in start order."""
        return {node.name: node.argv() for node in self.nodes()}


def bridge_params(
    mode: str,
    listen: tuple[str, ...],
    connect: tuple[str, ...],
    prefix: str,
    allow_remote: bool,
    rate_modules: object,
    linger_s: object,
    allow_option: str = "--zenoh-allow-remote",
    listen_option: str = "--zenoh-listen",
) -> dict[str, ParamValue]:
    """The Zenoh bridge's parameters from ``replay``'s options or the launch arguments,
    checked as the node checks them (ConfigError, one line), before any node starts, and
    its listen endpoints free; ``allow_option`` and ``listen_option``: how the refusals
    name the options to give instead."""
    from ads_rca.remote.config import DEFAULT_ENDPOINT, check_listen_free, session_config
    from ads_rca.remote.keys import check_prefix

    listen = listen or (DEFAULT_ENDPOINT,)
    session_config(mode, listen, connect, allow_remote, allow_option)
    params: dict[str, ParamValue] = {
        "zenoh_mode": mode,
        "zenoh_prefix": check_prefix(prefix, "zenoh_prefix"),
        "zenoh_allow_remote": allow_remote,
        "rate_modules": float(check_number("rate_modules", rate_modules, RATE)),
        "linger_s": float(check_number("zenoh_linger", linger_s, LINGER)),
    }
    if mode == "peer":
        params["zenoh_listen"] = listen
        check_listen_free(listen, listen_option)  # last: every value is right
    if connect:
        params["zenoh_connect"] = connect
    return params


@dataclass(frozen=True)
class LaunchArgument:
    """A launch argument of ``rca_graph.launch.py`` and the ``replay`` option it mirrors."""

    default: str
    description: str
    #: The ``argparse`` destination of the same option of ``ads-rca replay``.
    replay_option: str


#: The launch file's arguments: ``ads-rca replay``'s options for the graph, by launch name.
LAUNCH_ARGUMENTS: dict[str, LaunchArgument] = {
    "log_path": LaunchArgument(
        "",
        "Running-log folder, rosbag2 bag (dir, .mcap, .db3), CARLA run folder or DLP scene to "
        "play (required).",
        "path",
    ),
    "format": LaunchArgument(
        AUTO, f"The input's format: {', '.join(FORMATS)} (docs/formats.md).", "format"
    ),
    "ego_agent": LaunchArgument(
        "", "A DLP scene's ego: an agent token or number ('' = the default choice).", "ego_agent"
    ),
    "predictions": LaunchArgument(
        "", "A predictor's prediction files to score ('' = none).", "predictions"
    ),
    "submission": LaunchArgument(
        "", "An atmaCup #18 submission CSV to score ('' = none).", "submission"
    ),
    "derived_collision": LaunchArgument(
        "false",
        "A CARLA run's or DLP scene's collision is the first box overlap, flagged derived "
        "(default none).",
        "derived_collision",
    ),
    "bag_remap": LaunchArgument(
        "", "Topic remapping YAML for a bag whose topic names differ ('' = none).", "bag_remap"
    ),
    "profile": LaunchArgument(
        "ads_rca",
        "Profile of a bag: which topics and types carry the model's inputs (a built-in name "
        "or a YAML path).",
        "profile",
    ),
    "msg_path": LaunchArgument(
        "", "Directory of .msg files for types a bag does not define ('' = none).", "msg_path"
    ),
    "semantics": LaunchArgument(
        "",
        f"Oracle semantics, {' or '.join(SEMANTICS)} ('' = the params file's, else corrected).",
        "semantics",
    ),
    "params_file": LaunchArgument(
        "",
        "Engine parameters YAML, flat or a ROS 2 params file such as the installed "
        "config/rca_reference.yaml ('' = the mode's defaults).",
        "config",
    ),
    "event_time": LaunchArgument(
        "-1",
        "The critical event to explain when the run knows no collision: seconds from the "
        "recording's first message (-1 = the params file's; events are looked for).",
        "event_time",
    ),
    "record": LaunchArgument(
        "", "Record every topic to this new MCAP bag directory ('' = no recording).", "record"
    ),
    "rate": LaunchArgument(
        "0.0", "Playback rate against log time (0 = as fast as every node acknowledges).", "rate"
    ),
    "monitors": LaunchArgument(
        MONITORS_SHARED,
        "shared: the four monitors in one process (inputs decoded once); separate: one "
        "process each.",
        "monitors",
    ),
    "namespace": LaunchArgument(
        topics.DEFAULT_NAMESPACE,
        "Namespace of the contract topics (every node's topic_namespace).",
        "namespace",
    ),
    "max_file_mb": LaunchArgument(
        f"{DEFAULT_MAX_FILE_MB:g}",
        "Log files larger than this many MB are reported and skipped, not read.",
        "max_file_mb",
    ),
    "verdict_json": LaunchArgument(
        "", "Also write the verdict JSON to this file ('' = none).", "json_out"
    ),
    "zenoh": LaunchArgument(
        "false", "Start the zenoh_bridge node: results on Zenoh (docs/remote.md).", "zenoh"
    ),
    "zenoh_mode": LaunchArgument("peer", "Zenoh session mode: peer or client.", "zenoh_mode"),
    "zenoh_listen": LaunchArgument(
        "tcp/127.0.0.1:7447",
        "Zenoh endpoints to listen on, comma-separated (peer mode).",
        "zenoh_listen",
    ),
    "zenoh_connect": LaunchArgument(
        "", "Zenoh endpoints to connect to, comma-separated ('' = none).", "zenoh_connect"
    ),
    "zenoh_prefix": LaunchArgument("", "Key prefix of every Zenoh sample.", "zenoh_prefix"),
    "zenoh_allow_remote": LaunchArgument(
        "false",
        "Allow Zenoh endpoints off loopback (configure Zenoh TLS and access control then).",
        "zenoh_allow_remote",
    ),
    "rate_modules": LaunchArgument(
        "20.0", "Most JSON samples per second per module key on Zenoh (0 = all).", "rate_modules"
    ),
    "zenoh_linger": LaunchArgument(
        "30.0",
        "Seconds the bridge keeps serving the run to late dashboards after the verdict "
        "(inf: until Ctrl-C); the run ends then.",
        "zenoh_linger",
    ),
}
#: ``replay`` options that are no launch argument, and where a launch user finds them.
REPLAY_ONLY: dict[str, str] = {
    "params": "-p NAME=VALUE: put the values in params_file",
    "timeout": "--timeout: the launch runs until the verdict or a node fails",
    "domain_id": "--domain-id: ROS_DOMAIN_ID in the launch's environment",
    "allow_external_discovery": "--allow-external-discovery: the launch keeps its environment",
    "verbose": "--verbose: the launch shows every node's output",
}


def spec_from_arguments(values: Mapping[str, str]) -> GraphSpec:
    """The graph the launch file starts, from its arguments' values (strings, as
    ``LaunchConfiguration`` gives them); InputError (one line) for what cannot run, before
    any node starts. The aggregator exits after its verdict (the end of the run)."""

    def value(name: str) -> str:
        return str(values.get(name, LAUNCH_ARGUMENTS[name].default)).strip()

    log_path = value("log_path")
    if not log_path:
        raise InputError(
            "log_path is required: ros2 launch ads_rca rca_graph.launch.py "
            "log_path:=<log folder or bag>"
        )
    if not Path(log_path).exists():
        raise InputError(f"log_path {log_path}: no such log folder or bag")
    monitors = value("monitors")
    if monitors not in MONITOR_LAYOUTS:
        raise InputError(f"monitors must be {' or '.join(MONITOR_LAYOUTS)}, not {monitors!r}")
    rate = float(check_number("rate", value("rate"), RATE))
    params_file = value("params_file")
    event_time = value("event_time")
    given = (
        {} if event_time == LAUNCH_ARGUMENTS["event_time"].default else {"event_time_s": event_time}
    )
    params = params_from_sources(
        value("semantics") or None, load_config(params_file) if params_file else {}, given
    )
    max_file_mb = float(check_number("max_file_mb", value("max_file_mb"), MAX_FILE_MB))
    source = SourceOptions.from_values({name: value(name) for name in SOURCE_PARAMS})
    player: dict[str, ParamValue] = {"max_file_mb": max_file_mb, **source.as_params()}
    if value("bag_remap"):
        player["bag_remap"] = str(Path(value("bag_remap")).resolve())
    if value("profile"):
        profile = value("profile")
        player["profile"] = profile if profile in BUILTIN_PROFILES else str(Path(profile).resolve())
    if value("msg_path"):
        player["msg_path"] = str(Path(value("msg_path")).resolve())
    record, verdict_json = value("record"), value("verdict_json")
    zenoh = _flag("zenoh", value("zenoh"))
    zenoh_params = (
        bridge_params(
            value("zenoh_mode"),
            _endpoints(value("zenoh_listen")),
            _endpoints(value("zenoh_connect")),
            value("zenoh_prefix"),
            _flag("zenoh_allow_remote", value("zenoh_allow_remote")),
            value("rate_modules"),
            value("zenoh_linger"),
            allow_option="zenoh_allow_remote:=true",
            listen_option="zenoh_listen:=tcp/127.0.0.1:PORT",
        )
        if zenoh
        else None
    )
    return GraphSpec(
        log_path=Path(log_path).resolve(),
        params=params,
        verdict_json=Path(verdict_json).resolve() if verdict_json else None,
        namespace=value("namespace"),
        rate=rate,
        record=Path(record).resolve() if record else None,
        player_params=player,
        monitors=monitors,
        exit_after_verdict=True,
        zenoh_params=zenoh_params,
    )


def _flag(name: str, text: str) -> bool:
    if text.lower() not in ("true", "false"):
        raise InputError(f"{name} must be true or false, not {text[:40]!r}")
    return text.lower() == "true"


def _endpoints(text: str) -> tuple[str, ...]:
    return tuple(part.strip() for part in text.split(",") if part.strip())


def exit_status(code: int) -> str:
    """``status 2`` or ``killed by SIGSEGV``: how a child process ended."""
    if code >= 0:
        return f"status {code}"
    try:
        return f"killed by {signal.Signals(-code).name}"
    except ValueError:
        return f"killed by signal {-code}"


def exit_outcome(
    name: str, code: int, stopping: bool = False, last: str = "aggregator"
) -> tuple[bool, str] | None:
    """What node ``name`` exiting with ``code`` means for a launched graph (``stopping``:
    the launch is already shutting its nodes down).

    ``(True, why)``: the run is over (``last``, the spec's :attr:`GraphSpec.last_node`,
    exited 0: the aggregator once its verdict is acknowledged, or the Zenoh bridge once it
    forwarded it): stop the rest. ``(False, why)``: a node failed (any non-zero status,
    signals included, also while stopping): the graph cannot give a verdict, or did not
    stop cleanly; stop everything and fail. None: nothing to do (the player exits 0 after
    playing; every node exits 0 when stopped).
    """
    if code != 0:
        return False, f"{name} exited with {exit_status(code)}: the graph cannot give a verdict"
    if name == last and not stopping:
        if name == BRIDGE_NAME:
            return True, "run over: the Zenoh bridge forwarded the verdict"
        return True, "run over: the aggregator published the verdict"
    return None


class Graph:
    """A running graph; use as a context manager (everything stops on exit)."""

    def __init__(self, spec: GraphSpec, env: Mapping[str, str], echo: TextIO | None = None) -> None:
        self.spec = spec
        self.launcher = Launcher(env, echo=echo)
        self.started_at = 0.0

    def start(self, skip: tuple[str, ...] = ()) -> None:
        if self.spec.verdict_json is not None:
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
        if self.spec.verdict_json is None:
            return None
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

    def stop(self, player_grace_s: float = 10.0, keep: Collection[str] = ()) -> dict[str, int]:
        """Let the player finish (it exits after its acks), then stop the rest in reverse,
        but the nodes named in ``keep`` (``replay``'s lingering bridge)."""
        player = self.processes.get("player")
        if player is not None:
            player.wait(player_grace_s)
        return self.launcher.stop_all(keep=keep)

    def __enter__(self) -> Graph:
        return self

    def __exit__(self, *exc: object) -> None:
        self.launcher.stop_all()
