"""The ``main()`` every long-running node shares: init, build, spin, shut down cleanly.

A node that cannot start (bad parameter, unreadable input) logs one line and exits 2;
SIGINT/SIGTERM end the spin without a traceback; a node's optional ``close()`` runs before
it is destroyed (so files are finalised).

Signals only set a flag (:func:`stop_requested`): rclpy's own handlers are not installed
(``SignalHandlerOptions.NO``). Why: they chain to Python's, which raises KeyboardInterrupt
wherever the main thread is, and inside a callback that rclpy's C++ executor called the
exception crosses pybind11 and aborts the process ("terminate called after throwing an
instance of pybind11::error_already_set", exit -6). With a flag, every loop (the spin,
the player's waits, the recorder's drain) ends within one ``spin_once`` timeout, and the
node is closed, destroyed and rclpy shut down in order: exit status 0. A terminal's Ctrl-C
reaches every process of its group, and ``ros2 launch`` sends SIGINT again: a second
signal is counted, not an error.

Before ``rclpy.init`` every node checks its environment (:func:`prepare_process`): a bad
``ROS_DOMAIN_ID`` is one error line and exit 2, variables that can send discovery off the
machine are named in a warning, and Fast DDS is pointed at our profile (loopback
transport, fast acknowledgements) unless one is chosen.
"""

from __future__ import annotations

import os
import signal
import time
from collections.abc import Callable, Iterable, Mapping
from types import FrameType
from typing import Any

import rclpy
from rclpy.duration import Duration
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.logging import get_logger
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.signals import SignalHandlerOptions
from rclpy.subscription import RCLError, Subscription

from ads_rca.contract import live_topics, topics
from ads_rca.errors import AdsRcaError
from ads_rca.foundation.text import printable
from ads_rca.ros.env import domain_id_problem, node_warnings, use_node_profile
from ads_rca.ros.lifeline import die_with_parent

#: SIGINT/SIGTERM received by this process (see the module docstring).
_SIGNALS: list[int] = []


def _on_stop_signal(signum: int, frame: FrameType | None) -> None:
    _SIGNALS.append(signum)


def install_stop_handlers() -> None:
    """SIGINT and SIGTERM set the stop flag instead of raising (call before ``rclpy.init``)."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _on_stop_signal)


def ignore_stop_signals() -> None:
    """Once the node is shut down: further SIGINT/SIGTERM are ignored. Why: Python's
    finalisation puts its own handlers back to SIG_DFL (not an ignored one), so a group
    signal arriving while the interpreter exits would kill the process (status -2) after a
    clean stop."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)


def stop_requested() -> int:
    """How many stop signals arrived (0: keep going)."""
    return len(_SIGNALS)


def keep_running() -> bool:
    """No stop signal yet and the ROS context is still valid."""
    return not _SIGNALS and rclpy.ok()


def wait_for_acks(
    publishers: Iterable[Publisher[Any]], timeout_s: float, signals_allowed: int = 0
) -> bool:
    """Every subscriber of ``publishers`` acknowledged every message; False after
    ``timeout_s`` or on a stop signal (checked every 0.1 s: the wait is in C++).
    ``signals_allowed``: stop signals that already came and do not end the wait (a node
    flushing on its way out after the first one: a second still ends it at once)."""
    deadline = time.monotonic() + timeout_s
    slice_ = Duration(seconds=0.1)
    waiting = list(publishers)
    while stop_requested() <= signals_allowed and rclpy.ok():
        waiting = [p for p in waiting if not p.wait_for_all_acked(slice_)]
        if not waiting:
            return True
        if time.monotonic() > deadline:
            return False
    return False


def make_executor(message_info: bool = False) -> Executor:
    """rclpy's C++ events executor where available, else the single-threaded one.

    Why: the Python executor rebuilds its wait set for every callback it runs; at rate 0
    that bookkeeping cost the aggregator more CPU than its own work. The events executor
    dispatches from a C++ event queue (same single-threaded callback semantics), but (rclpy
    9.1) it cannot call a callback that takes the MessageInfo (``SystemError: null argument
    to internal routine``): nodes with such callbacks ask for ``message_info``.
    """
    if message_info:
        return SingleThreadedExecutor()
    try:
        from rclpy.experimental.events_executor import EventsExecutor
    except ImportError:
        return SingleThreadedExecutor()
    return EventsExecutor()


def prepare_process(name: str) -> bool:
    """Check and set up this node process's environment before ``rclpy.init``; False: the
    node cannot start (the reason was logged)."""
    die_with_parent()
    logger = get_logger(name)
    problem = domain_id_problem()
    if problem is not None:
        logger.error(problem)
        return False
    for line in node_warnings(os.environ):
        logger.warning(line)
    use_node_profile()
    return True


def start_process(name: str, args: list[str] | None) -> bool:
    """:func:`install_stop_handlers`, :func:`prepare_process`, then ``rclpy.init`` without
    rclpy's signal handlers; False: the node cannot start, and one line says why. rcl
    refuses command-line arguments it cannot parse (a ``-p`` value that is not YAML, a bad
    remapping) with an exception whose text spans lines; that is one error line here,
    never a traceback."""
    install_stop_handlers()
    if not prepare_process(name):
        return False
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except (RCLError, ValueError) as error:
        reason = next((line for line in str(error).splitlines() if line.strip()), "")
        get_logger(name).error(printable(f"cannot start: bad ROS arguments: {reason}"))
        return False
    return True


def run_node(
    name: str,
    build: Callable[[], Node | list[Node]],
    args: list[str] | None = None,
    startup_errors: tuple[type[Exception], ...] = (AdsRcaError,),
    message_info: bool = False,
) -> int:
    """Run the node(s) ``build()`` makes until a stop signal, or until one of them says it
    is ``finished`` (an attribute, e.g. the aggregator after its verdict); exit status 0, or
    2 if they cannot start. Several nodes share one executor (one thread: callbacks never
    overlap); ``message_info``: some callbacks take the MessageInfo (see
    :func:`make_executor`)."""
    if not start_process(name, args):
        return 2
    nodes: list[Node] = []
    try:
        try:
            built = build()
            nodes = built if isinstance(built, list) else [built]
        except startup_errors as error:
            get_logger(name).error(str(error))
            return 2
        executor = make_executor(message_info)
        for node in nodes:
            executor.add_node(node)
        while keep_running() and not any(getattr(n, "finished", False) for n in nodes):
            executor.spin_once(timeout_sec=0.1)
        return 0
    except (KeyboardInterrupt, ExternalShutdownException):
        return 0
    finally:
        for node in nodes:
            close = getattr(node, "close", None)
            if callable(close):
                close()
            node.destroy_node()
        rclpy.try_shutdown()
        ignore_stop_signals()


def subscribe_ready(node: Node, namespace: str, run_id: str) -> None:
    """Be counted by the player of run ``run_id`` before it plays (nothing if no run id;
    see :func:`ads_rca.contract.live_topics.ready_key`)."""
    if not run_id:
        return
    from std_msgs.msg import String

    name = topics.topic_name(live_topics.ready_key(run_id), namespace)
    node.create_subscription(String, name, _ignore, 1)


def subscribe_ready_once_matched(
    node: Node,
    namespace: str,
    run_id: str,
    subscriptions: Mapping[str, Subscription[Any] | None],
    timeout_s: float,
) -> None:
    """:func:`subscribe_ready` once each of ``subscriptions`` (topic → subscription) has
    matched a publisher, or ``timeout_s`` passed (a warning names the topics still alone).

    Why: the player waits for every node's ready subscription, not for the nodes to find
    each other. A recorder or bridge that had not yet matched the monitors when a short
    run ended, stopped before their results reached it (CI: a replay's bag without one
    metrics message). Waiting here makes the player wait for that match too. Polled on a
    node timer, so the node spins meanwhile; nothing (0 s, no run id) waits at once.
    """
    waiting = {name: sub for name, sub in subscriptions.items() if sub is not None}
    if not run_id or timeout_s <= 0 or not waiting:
        subscribe_ready(node, namespace, run_id)
        return
    deadline = time.monotonic() + timeout_s

    def check() -> None:
        alone = [name for name, sub in waiting.items() if sub.get_publisher_count() < 1]
        if alone and time.monotonic() < deadline:
            return
        timer.cancel()
        if alone:
            node.get_logger().warning(
                f"no publisher of {', '.join(sorted(alone))} after {timeout_s:g} s; ready anyway"
            )
        subscribe_ready(node, namespace, run_id)

    timer = node.create_timer(0.02, check)


def _ignore(msg: object) -> None:
    """Nothing is ever published on the ready topic."""
