"""The ``main()`` every long-running node shares: init, build, spin, shut down cleanly.

A node that cannot start (bad parameter, unreadable input) logs one line and exits 2;
SIGINT/SIGTERM end the spin without a traceback; a node's optional ``close()`` runs before
it is destroyed (so files are finalised). Before ``rclpy.init`` every node checks its
environment (:func:`prepare_process`): a bad ``ROS_DOMAIN_ID`` is one error line and exit 2,
variables that can send discovery off the machine are named in a warning, and Fast DDS is
pointed at our profile (loopback transport, fast acknowledgements) unless one is chosen.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

import rclpy
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.logging import get_logger
from rclpy.node import Node
from rclpy.subscription import RCLError

from ads_rca.contract import live_topics, topics
from ads_rca.errors import InputError
from ads_rca.ros.env import domain_id_problem, node_warnings, use_node_profile
from ads_rca.ros.lifeline import die_with_parent
from ads_rca.text import printable


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


def start_process(name: str, args: list[str] | None, **init: Any) -> bool:
    """:func:`prepare_process`, then ``rclpy.init`` (``init``: its keyword arguments);
    False: the node cannot start, and one line says why. rcl refuses command-line
    arguments it cannot parse (a ``-p`` value that is not YAML, a bad remapping) with an
    exception whose text spans lines; that is one error line here, never a traceback."""
    if not prepare_process(name):
        return False
    try:
        rclpy.init(args=args, **init)
    except (RCLError, ValueError) as error:
        reason = next((line for line in str(error).splitlines() if line.strip()), "")
        get_logger(name).error(printable(f"cannot start: bad ROS arguments: {reason}"))
        return False
    return True


def run_node(
    name: str,
    build: Callable[[], Node | list[Node]],
    args: list[str] | None = None,
    startup_errors: tuple[type[Exception], ...] = (InputError,),
    message_info: bool = False,
) -> int:
    """Run the node(s) ``build()`` makes until shutdown; exit status 0, or 2 if they cannot
    start. Several nodes share one executor (one thread: callbacks never overlap);
    ``message_info``: some callbacks take the MessageInfo (see :func:`make_executor`)."""
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
        while rclpy.ok():
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


def subscribe_ready(node: Node, namespace: str, run_id: str) -> None:
    """Be counted by the player of run ``run_id`` before it plays (nothing if no run id;
    see :func:`ads_rca.contract.live_topics.ready_key`)."""
    if not run_id:
        return
    from std_msgs.msg import String

    name = topics.topic_name(live_topics.ready_key(run_id), namespace)
    node.create_subscription(String, name, _ignore, 1)


def _ignore(msg: Any) -> None:
    """Nothing is ever published on the ready topic."""
