"""The ``main()`` every long-running node shares: init, build, spin, shut down cleanly.

A node that cannot start (bad parameter, unreadable input) logs one line and exits 2;
SIGINT/SIGTERM end the spin without a traceback; a node's optional ``close()`` runs before
it is destroyed (so files are finalised).
"""

from __future__ import annotations

from collections.abc import Callable

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.logging import get_logger
from rclpy.node import Node

from ads_rca.errors import InputError


def run_node(
    name: str,
    build: Callable[[], Node],
    args: list[str] | None = None,
    startup_errors: tuple[type[Exception], ...] = (InputError,),
) -> int:
    """Run the node ``build()`` makes until shutdown; exit status 0, or 2 if it cannot start."""
    rclpy.init(args=args)
    node: Node | None = None
    try:
        try:
            node = build()
        except startup_errors as error:
            get_logger(name).error(str(error))
            return 2
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        while rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
        return 0
    except (KeyboardInterrupt, ExternalShutdownException):
        return 0
    finally:
        if node is not None:
            close = getattr(node, "close", None)
            if callable(close):
                close()
            node.destroy_node()
        rclpy.try_shutdown()
