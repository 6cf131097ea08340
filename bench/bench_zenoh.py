"""The Zenoh bridge on loopback: throughput, ROS publish -> Zenoh delivery latency, CPU per
message, and the web dashboard's update latency (issue #17).

Why: the bridge sits between the live graph and every remote dashboard; it must keep up
with the monitors' results without losing one, and a dashboard should show a frame soon
after a monitor published it. Everything runs on this machine: the bridge node is its own
process on a private DDS domain (local-only discovery), its Zenoh endpoint a free port on
127.0.0.1, every session with multicast and gossip scouting off.

1. Bridge. This process publishes realistic perception results (a LiveResult's strict JSON,
   each with its own frame index, the publish time kept per index) on
   ``<ns>/metrics/perception`` with the monitors' QoS, N messages at full speed, then N at a
   fixed rate (default 200 Hz). A Zenoh client session in this same process subscribes to
   the raw CDR key (``bench/<ns>/metrics/perception``) and to the JSON key
   (``bench/ads_rca/modules/perception.json``); its callbacks only note the time and keep
   the bytes (decoded afterwards). In this process rather than a separate one: one clock
   for publish and delivery, and on a two-CPU machine a third busy process would compete
   with the bridge. Reported per phase and key: messages/s delivered (messages / (last
   delivery - first publish)), latency from ROS publish to Zenoh delivery p50/p99, lost
   (must be 0) and duplicates. The full-speed latency is mostly queueing (the publisher
   outruns the bridge); read the fixed-rate one. The bridge runs with rate_modules 0 and
   rate_raw 0 (every message forwarded both ways), heartbeat_s 1.

   Bridge CPU: user + system seconds from /proc/<pid>/stat between the phase's first
   publish and its last delivery, per message; also without its idle CPU (timers,
   heartbeat, DDS; measured over 3 s, 10 ms clock ticks), and split by thread from
   /proc/<pid>/task: ``python`` (rclpy's executor and every Python callback), ``zenoh``
   (its runtime's tx/rx threads), ``dds`` (Fast DDS). At a fixed rate every message wakes
   the threads on its own, so it costs more than at full speed. The table's ``wall s`` and
   ``CPU s`` are the phase's (first publish to last delivery; CPU of the bridge and of this
   process, publisher and subscribers). A last line times the bridge's JSON work alone in
   this process (decode the CDR string, ``RemoteState.on_result``: parse, validate,
   re-serialise), without ROS or Zenoh, wall and CPU: a cross-check of the CPU figure's
   Python part.
2. Dashboard. ``ads-rca dashboard --connect <bridge endpoint>`` runs as its own process;
   this process reads its server-sent events (``/events``) with aiohttp and publishes
   results at 20 Hz. The latency of a frame is from its ROS publish to the first event whose
   run shows that index (``last_index``). The dashboard coalesces events (at most one per
   0.1 s to a browser) and drains Zenoh every 0.05 s, so up to ~150 ms of it is by design.
   The phase's wall time and the CPU of the dashboard, the bridge and this process follow.

Every process is stopped with SIGINT and waited for; none outlives the bench (checked).
Default run: under 2 minutes.

Usage: ``python bench/bench_zenoh.py [--messages 5000] [--rate 200] [--dashboard-frames 200]
[--dashboard-rate 20]``.
"""

from __future__ import annotations

import argparse
import asyncio
import atexit
import contextlib
import math
import os
import re
import shutil
import socket
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import orjson
from timing import Clock, Timing, process_cpu_s

from ads_rca.contract.cdr_decode import decode_string
from ads_rca.contract.jsontext import dumps_json
from ads_rca.contract.live_topics import metrics_qos
from ads_rca.live.results import LiveResult
from ads_rca.oracles.base import OracleResult
from ads_rca.oracles.corrected.common import REPORTED
from ads_rca.params import make_params
from ads_rca.remote.config import session_config
from ads_rca.remote.session import close_session
from ads_rca.remote.state import RemoteState
from ads_rca.ros.env import apply_to_current_process, pick_domain_id, ros_environment
from ads_rca.ros.launcher import ManagedProcess, ros_args

PREFIX = "bench"
#: How long to wait for the last deliveries of a phase after its last publish (s).
DRAIN_S = 15.0
#: The corrected perception oracle's reported thresholds, as its results carry them.
THRESHOLDS: dict[str, float] = make_params("corrected").values(REPORTED["perception"])


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def thread_cpu(pid: int) -> dict[tuple[str, str], float]:
    """(thread id, name) -> user + system CPU seconds of each thread of a process."""
    out = {}
    try:
        tasks = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return {}
    for tid in tasks:
        try:
            name = Path(f"/proc/{pid}/task/{tid}/comm").read_text().strip()
            fields = Path(f"/proc/{pid}/task/{tid}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue  # the thread ended
        out[(tid, name)] = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    return out


def thread_group(name: str) -> str:
    """Which part of the bridge a thread is: the interpreter (rclpy's executor and every
    Python callback), Zenoh's runtime (``tx-0``, ``rx-0``, ``net-0``, ``acc-0``, ``app-0``)
    or Fast DDS (``dds.*``)."""
    if name.startswith("python"):
        return "python"
    if name.startswith("dds."):
        return "dds"
    if re.match(r"^(tx|rx|net|acc|app)-[0-9]+$", name):
        return "zenoh"
    return "other"


def result_text(index: int) -> str:
    """A perception monitor's result for frame ``index`` as it publishes it: the corrected
    oracle's metrics and thresholds for a frame where the partner is missed (~1.2 kB)."""
    metrics: dict[str, Any] = {
        "detections": 11,
        "gt_boxes": 12,
        "matched": 10,
        "precision": 10 / 11,
        "recall": 10 / 12,
        "mean_iou": 0.7813,
        "missed": {"veh_17": 0.2141, "ped_3": 0.0},
        "false_positives": ["det_41"],
        "partner_in_view": True,
        "partner_matched": False,
        "partner_best_iou": 0.2141,
        "unconditioned": True,
        "perception_floor": 0.12,
        "perception_floor_frames": 40,
        "perception_floor_basis": "early frames",
        "noise_allowance": 0.24,
        "real_conflict": True,
        "planner_input_degraded": True,
        "raw_linked": True,
        "raw_displacement": 1.93,
        "displacement_threshold": 0.8,
        "c_gt": 0.31 + (index % 50) / 100,
        "c_gt_index": 12,
        "c_raw": 2.4,
        "c_raw_index": 14,
        "c_ref": float("nan"),
        "c_ref_index": None,
    }
    result = OracleResult(
        "perception",
        1_700_000_000_000 + index * 50,
        True,
        metrics,
        THRESHOLDS,
        ("veh_17", "raw_9"),
    )
    live = LiveResult(
        index,
        result,
        index,
        collision_frame=4000,
        ego_id="ego",
        partner_id="veh_17",
        compute_s=0.0021,
        wait_s=0.004,
        session="bench-0001",
        run="bench-run",
    )
    return dumps_json(live.to_document())


def percentiles(values: list[float]) -> tuple[float, float]:
    if not values:
        return math.nan, math.nan
    p50, p99 = np.percentile(np.array(values) * 1000.0, [50, 99])
    return float(p50), float(p99)


@dataclass
class Receiver:
    """What a Zenoh subscriber got: (perf_counter time, payload), appended on zenoh's thread."""

    index_of: Callable[[bytes], int]
    got: list[tuple[float, bytes]] = field(default_factory=list)

    def on_sample(self, sample: Any) -> None:
        self.got.append((time.perf_counter(), sample.payload.to_bytes()))

    def first_arrivals(self, since: int = 0) -> dict[int, float]:
        """Index -> time of its first delivery, of the samples from position ``since``."""
        out: dict[int, float] = {}
        for at, payload in self.got[since:]:
            out.setdefault(self.index_of(payload), at)
        return out


def raw_index(payload: bytes) -> int:
    return int(orjson.loads(decode_string(payload))["index"])


def json_index(payload: bytes) -> int:
    return int(orjson.loads(payload)["index"])


@dataclass
class Phase:
    name: str
    sent: dict[int, float]
    cpu_s: float
    wall_s: float
    delivered: dict[str, dict[int, float]]
    duplicates: dict[str, int]
    threads: dict[str, float]
    #: This process's CPU seconds over the phase (publishing, Zenoh's callbacks).
    own_cpu_s: float


def wait_for(condition: Callable[[], bool], timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise SystemExit(f"bench_zenoh: timed out waiting for {what}")
        time.sleep(0.01)


class Bench:
    """The bridge process, this process's ROS publisher and Zenoh subscribers."""

    def __init__(self, work: Path) -> None:
        self.domain = pick_domain_id()
        apply_to_current_process(self.domain)  # before rclpy.init: local-only, our domain
        self.env = ros_environment(domain_id=self.domain, log_dir=work / "ros_log")
        self.namespace = f"/bench_zenoh_{os.getpid()}"
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.next_index = 0
        self.processes: list[ManagedProcess] = []
        self.receivers = {
            "raw": Receiver(raw_index),
            "json": Receiver(json_index),
        }
        self.keys = {
            "raw": f"{PREFIX}{self.namespace}/metrics/perception",
            "json": f"{PREFIX}/ads_rca/modules/perception.json",
        }
        self._session: Any = None
        self._subscribers: list[Any] = []
        self._context: Any = None
        self._node: Any = None

    # Processes ---------------------------------------------------------------------

    def start_bridge(self) -> ManagedProcess:
        params: dict[str, Any] = {
            "topic_namespace": self.namespace,
            "bridge_topics": ("metrics/perception",),
            "zenoh_mode": "peer",
            "zenoh_listen": (self.endpoint,),
            "zenoh_prefix": PREFIX,
            "rate_modules": 0.0,
            "rate_raw": 0.0,
            "heartbeat_s": 1.0,
        }
        argv = [sys.executable, "-m", "ads_rca.ros.zenoh_bridge", *ros_args(params)]
        self.bridge = ManagedProcess("zenoh_bridge", argv, self.env)
        self.processes.append(self.bridge)
        return self.bridge

    def start_dashboard(self) -> str:
        port = free_port()
        argv = [sys.executable, "-m", "ads_rca.cli", "dashboard", "--connect", self.endpoint]
        argv += ["--port", str(port)]
        self.dashboard = ManagedProcess("dashboard", argv, self.env)
        self.processes.append(self.dashboard)
        wait_for(
            lambda: (
                "ads-rca dashboard: http" in self.dashboard.output
                or self.dashboard.returncode is not None
            ),
            30,
            "the dashboard to serve",
        )
        found = re.search(r"ads-rca dashboard: (http://\S+)", self.dashboard.output)
        if found is None:
            raise SystemExit(f"bench_zenoh: the dashboard did not start:\n{self.dashboard.output}")
        return found.group(1)

    def stop_all(self) -> list[str]:
        """SIGINT each process (last started first), wait; a line per process."""
        lines = []
        for process in reversed(self.processes):
            started = time.monotonic()
            code = process.stop(timeout=10.0)
            took = time.monotonic() - started
            try:
                os.killpg(process.process.pid, 0)
                alive = True
            except ProcessLookupError:
                alive = False
            except PermissionError:
                alive = True
            traceback = "Traceback" in process.output
            lines.append(
                f"{process.name}: exit {code} after SIGINT in {took:.2f} s"
                f"{'; PROCESS GROUP STILL ALIVE' if alive else ''}"
                f"{'; TRACEBACK in its output' if traceback else ''}"
            )
        self.processes.clear()
        return lines

    # ROS and Zenoh in this process -------------------------------------------------

    def open(self) -> None:
        import rclpy
        import zenoh
        from std_msgs.msg import String

        self.String = String
        self._context = rclpy.Context()
        rclpy.init(args=[], context=self._context)
        self._node = rclpy.create_node("bench_zenoh", context=self._context)
        self.publisher = self._node.create_publisher(
            String, f"{self.namespace}/metrics/perception", metrics_qos()
        )
        config = zenoh.Config.from_json5(session_config("client", [], [self.endpoint]))
        deadline = time.monotonic() + 30
        while self._session is None:
            try:
                self._session = zenoh.open(config)
            except zenoh.ZError:
                if time.monotonic() > deadline or self.bridge.returncode is not None:
                    raise SystemExit(
                        f"bench_zenoh: no Zenoh session:\n{self.bridge.output}"
                    ) from None
                time.sleep(0.1)
        for kind, receiver in self.receivers.items():
            self._subscribers.append(
                self._session.declare_subscriber(self.keys[kind], receiver.on_sample)
            )
        wait_for(lambda: self.publisher.get_subscription_count() >= 1, 30, "the bridge's DDS match")

    def close_zenoh(self) -> None:
        session, self._session = self._session, None
        subscribers, self._subscribers = self._subscribers, []
        close_session(session, subscribers)

    def close(self) -> None:
        import rclpy

        self.close_zenoh()
        if self._node is not None:
            self._node.destroy_node()
            self._node = None
        if self._context is not None:
            rclpy.shutdown(context=self._context)
            self._context = None

    def messages(self, count: int) -> list[tuple[int, Any]]:
        """The next ``count`` results (fresh indices), built before any is timed."""
        indices = range(self.next_index, self.next_index + count)
        out = [(index, self.String(data=result_text(index))) for index in indices]
        self.next_index += count
        return out

    def warm_up(self) -> None:
        """Results until one went through both keys: the routes exist end to end."""
        marks = {kind: len(r.got) for kind, r in self.receivers.items()}
        deadline = time.monotonic() + 30
        while not all(len(r.got) > marks[k] for k, r in self.receivers.items()):
            if time.monotonic() > deadline:
                raise SystemExit(f"bench_zenoh: nothing through the bridge:\n{self.bridge.output}")
            for _, message in self.messages(1):
                self.publisher.publish(message)
            time.sleep(0.05)
        time.sleep(0.5)

    def idle_cpu(self, seconds: float) -> float:
        """The bridge's CPU seconds per second with nothing to forward."""
        before = process_cpu_s(self.bridge.process.pid)
        time.sleep(seconds)
        return (process_cpu_s(self.bridge.process.pid) - before) / seconds

    def run_phase(self, name: str, count: int, rate: float | None) -> Phase:
        batch = self.messages(count)
        marks = {kind: len(r.got) for kind, r in self.receivers.items()}
        sent: dict[int, float] = {}
        pid = self.bridge.process.pid
        threads0 = thread_cpu(pid)
        cpu0 = process_cpu_s(pid)
        own = Clock().start()
        start = time.perf_counter()
        publish = self.publisher.publish
        if rate is None:
            for index, message in batch:
                sent[index] = time.perf_counter()
                publish(message)
        else:
            period = 1.0 / rate
            for n, (index, message) in enumerate(batch):
                delay = start + n * period - time.perf_counter()
                if delay > 0:
                    time.sleep(delay)
                sent[index] = time.perf_counter()
                publish(message)
        wanted = set(sent)

        def received(kind: str) -> set[int]:
            receiver = self.receivers[kind]
            return set(receiver.first_arrivals(marks[kind])) & wanted

        last_progress, last_counts = time.monotonic(), (-1, -1)
        while True:
            counts = (len(self.receivers["raw"].got), len(self.receivers["json"].got))
            if counts != last_counts:
                last_counts, last_progress = counts, time.monotonic()
                if all(
                    len(self.receivers[k].got) - marks[k] >= count for k in self.receivers
                ) and all(received(k) == wanted for k in self.receivers):
                    break
            if time.monotonic() - last_progress > DRAIN_S:
                break
            time.sleep(0.05)
        delivered = {
            kind: {i: t for i, t in r.first_arrivals(marks[kind]).items() if i in wanted}
            for kind, r in self.receivers.items()
        }
        last = max((max(d.values()) for d in delivered.values() if d), default=start)
        cpu = process_cpu_s(pid) - cpu0
        own_cpu = own.cpu_s
        threads: dict[str, float] = {}
        for thread, seconds in thread_cpu(pid).items():
            group = thread_group(thread[1])
            threads[group] = threads.get(group, 0.0) + seconds - threads0.get(thread, 0.0)
        duplicates = {
            kind: len(r.got) - marks[kind] - len(delivered[kind])
            for kind, r in self.receivers.items()
        }
        return Phase(name, sent, cpu, last - start, delivered, duplicates, threads, own_cpu)

    # The dashboard ---------------------------------------------------------------------

    async def dashboard_latency(self, url: str, frames: int, rate: float) -> dict[str, Any]:
        import aiohttp

        batch = self.messages(frames)
        sent: dict[int, float] = {}
        events: list[tuple[float, int]] = []  # (time, last_index of our run)
        seen_run = asyncio.Event()
        done = asyncio.Event()
        last_index = batch[-1][0]

        async def read(response: aiohttp.ClientResponse) -> None:
            while True:
                line = await response.content.readline()
                if not line:
                    return
                if not line.startswith(b"data: "):
                    continue
                at = time.perf_counter()
                document = orjson.loads(line[6:])
                if PREFIX in document.get("names", ()):
                    seen_run.set()
                for run in document.get("runs", ()):
                    if run.get("run") == PREFIX and isinstance(run.get("last_index"), int):
                        events.append((at, run["last_index"]))
                        if run["last_index"] >= last_index:
                            done.set()

        async def publish() -> None:
            await asyncio.wait_for(seen_run.wait(), 30)
            await asyncio.sleep(0.5)
            start = time.perf_counter()
            for n, (index, message) in enumerate(batch):
                delay = start + n / rate - time.perf_counter()
                if delay > 0:
                    await asyncio.sleep(delay)
                sent[index] = time.perf_counter()
                self.publisher.publish(message)

        timeout = aiohttp.ClientTimeout(total=None, sock_read=None)
        async with (
            aiohttp.ClientSession(timeout=timeout) as session,
            session.get(url + "events") as response,
        ):
            reader = asyncio.ensure_future(read(response))
            try:
                await publish()
                await asyncio.wait_for(done.wait(), DRAIN_S)
            except TimeoutError:
                pass
            finally:
                reader.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await reader
        latencies = []
        first_event = 0
        for index, at in sorted(sent.items()):
            while first_event < len(events) and events[first_event][1] < index:
                first_event += 1
            if first_event < len(events):
                latencies.append(events[first_event][0] - at)
        in_phase = [e for e in events if sent and e[0] >= min(sent.values())]
        span = max(sent.values()) - min(sent.values()) if sent else 0.0
        return {
            "frames": len(sent),
            "shown": len(latencies),
            "latency": latencies,
            "events_per_s": len(in_phase) / span if span > 0 else math.nan,
        }


def json_work_per_message(count: int) -> Timing:
    """Wall and CPU seconds per message of the bridge's JSON side alone (CDR string decode
    and ``RemoteState.on_result``), in this process, on the same texts."""
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    payloads = [serialize_message(String(data=result_text(i))) for i in range(count)]
    state = RemoteState(PREFIX, 2000, {"modules": 0.0})
    with Clock() as clock:
        for n, payload in enumerate(payloads):
            state.on_result(decode_string(payload), float(n))
    return Timing(clock.wall_s / count, clock.cpu_s / count)


def phase_rows(phase: Phase, idle: float) -> list[str]:
    count = len(phase.sent)
    first = min(phase.sent.values())
    publish_span = max(phase.sent.values()) - first
    rows = []
    whole = f"{phase.wall_s:>7.2f} {phase.cpu_s + phase.own_cpu_s:>7.2f}"
    for kind in ("raw", "json"):
        delivered = phase.delivered[kind]
        latency = [t - phase.sent[i] for i, t in delivered.items()]
        p50, p99 = percentiles(latency)
        span = max(delivered.values()) - first if delivered else math.nan
        rate = len(delivered) / span if span and span > 0 else math.nan
        rows.append(
            f"  {phase.name:<11} {kind:<5} {count:>6} {count / max(publish_span, 1e-9):>9.0f}"
            f" {rate:>9.0f} {p50:>8.2f} {p99:>8.2f} {count - len(delivered):>5}"
            f" {phase.duplicates[kind]:>4} {whole}".rstrip()
        )
        whole = ""
    net = phase.cpu_s - idle * phase.wall_s
    rows.append(
        f"  {'':<11} bridge CPU {phase.cpu_s:.2f} s in {phase.wall_s:.2f} s = "
        f"{phase.cpu_s / count * 1e6:.0f} us/message ({net / count * 1e6:.0f} us without the "
        f"idle {idle * 1000:.1f} ms/s); {phase.cpu_s / max(phase.wall_s, 1e-9) * 100:.0f}% of a CPU"
    )
    rows.append(f"  {'':<11} this process CPU {phase.own_cpu_s:.2f} s (publisher, subscribers)")
    parts = ", ".join(
        f"{group} {seconds / count * 1e6:.0f}"
        for group, seconds in sorted(phase.threads.items(), key=lambda item: -item[1])
        if seconds > 0
    )
    rows.append(f"  {'':<11} by thread (us/message): {parts}")
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--messages", type=int, default=5000, help="per bridge phase")
    parser.add_argument("--rate", type=float, default=200.0, help="the fixed-rate phase (Hz)")
    parser.add_argument("--dashboard-frames", type=int, default=200)
    parser.add_argument("--dashboard-rate", type=float, default=20.0, help="Hz")
    args = parser.parse_args()
    if args.messages < 1 or args.rate <= 0 or args.dashboard_frames < 1 or args.dashboard_rate <= 0:
        parser.error("counts and rates must be positive")
    work = Path(tempfile.mkdtemp(prefix="ads_rca_bench_zenoh_"))
    atexit.register(shutil.rmtree, work, True)  # logs, metrics, ROS logs
    bench = Bench(work)
    size = len(result_text(0).encode())
    print(
        f"zenoh bridge on loopback: ROS domain {bench.domain} (discovery LOCALHOST), "
        f"Zenoh {bench.endpoint}; results of {size} B JSON; {os.cpu_count()} CPUs"
    )
    stops: list[str] = []
    try:
        bench.start_bridge()
        bench.open()
        bench.warm_up()
        idle = bench.idle_cpu(3.0)
        full = bench.run_phase("full speed", args.messages, None)
        paced = bench.run_phase(f"{args.rate:g} Hz", args.messages, args.rate)
        bench.close_zenoh()  # only the dashboard reads from here on
        url = bench.start_dashboard()
        pids = {"dashboard": bench.dashboard.process.pid, "bridge": bench.bridge.process.pid}
        before = {name: process_cpu_s(pid) for name, pid in pids.items()}
        with Clock() as own:
            board = asyncio.run(
                bench.dashboard_latency(url, args.dashboard_frames, args.dashboard_rate)
            )
        board_cpu = {name: process_cpu_s(pid) - before[name] for name, pid in pids.items()}
        board_cpu["this process"] = own.cpu_s
    finally:
        try:
            bench.close()
        finally:
            stops = bench.stop_all()
    print(
        "\n1. ROS publish -> Zenoh delivery (bridge: rate_modules 0, rate_raw 0; "
        "raw = CDR key, json = modules/perception.json)"
    )
    print(
        f"  {'phase':<11} {'key':<5} {'sent':>6} {'pub/s':>9} {'deliv/s':>9} "
        f"{'p50 ms':>8} {'p99 ms':>8} {'lost':>5} {'dup':>4} {'wall s':>7} {'CPU s':>7}"
    )
    for phase in (full, paced):
        for row in phase_rows(phase, idle):
            print(row)
    work_s = json_work_per_message(min(args.messages, 2000))
    print(
        f"  cross-check: the JSON side alone (decode + RemoteState.on_result, no ROS/Zenoh) "
        f"{work_s.wall_s * 1e6:.0f} us/message wall, {work_s.cpu_s * 1e6:.0f} us CPU, "
        "in this process"
    )
    p50, p99 = percentiles(board["latency"])
    print(
        f"\n2. ROS publish -> dashboard SSE event showing the frame ({args.dashboard_rate:g} Hz, "
        f"{board['frames']} frames; events coalesced to <= 10/s, Zenoh drained every 50 ms)"
    )
    print(
        f"  p50 {p50:.1f} ms  p99 {p99:.1f} ms; {board['shown']}/{board['frames']} frames shown; "
        f"{board['events_per_s']:.1f} events/s"
    )
    cpu_parts = ", ".join(f"{name} {seconds:.2f} s" for name, seconds in board_cpu.items())
    print(f"  wall {own.wall_s:.2f} s; CPU {sum(board_cpu.values()):.2f} s ({cpu_parts})")
    print("\n3. shutdown")
    for line in stops:
        print(f"  {line}")
    lost = sum(len(p.sent) - len(p.delivered[k]) for p in (full, paced) for k in p.delivered)
    return 1 if lost or any("ALIVE" in s or "TRACEBACK" in s for s in stops) else 0


if __name__ == "__main__":
    sys.exit(main())
