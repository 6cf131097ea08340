"""``topic_summary`` node: listens to every contract topic, counts, optionally rebuilds the log.

The separate-process subscriber of the demo and the tests. It counts messages per topic,
feeds them to the :class:`~ads_rca.contract.assembler.RunLogAssembler`, and stops when the player
said "finished" and everything the frame markers announced has arrived (or at ``timeout_s``).
With ``output_json`` it writes the rebuilt log as a running-log folder to ``output_dir``;
``summary_file`` receives the per-topic counts as JSON. Exit status: 0 complete, 1 timed out.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

import orjson
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.logging import get_logger
from rclpy.node import Node

from ads_rca.contract import topics
from ads_rca.contract.assembler import RunLogAssembler
from ads_rca.contract.errors import ContractError, MalformedMessage
from ads_rca.contract.malformed import SkippedMessages
from ads_rca.errors import AdsRcaError
from ads_rca.foundation.strictjson import to_strict
from ads_rca.paramspec import Range
from ads_rca.ros.nodemain import (
    ignore_stop_signals,
    keep_running,
    make_executor,
    start_process,
    stop_requested,
)
from ads_rca.ros.nodeparams import (
    NodeParameter,
    command_line_overrides,
    declare_node_parameters,
    log_in_force,
)

PARAMETERS: dict[str, NodeParameter] = {
    "topic_namespace": (topics.DEFAULT_NAMESPACE, "Namespace of the contract topics."),
    "output_json": (False, "Rebuild the log from the messages and write it to output_dir."),
    "output_dir": ("rebuilt_log", "Folder for the rebuilt running log (with output_json)."),
    "summary_file": ("", "Write the per-topic counts as JSON to this file ('' = no file)."),
    "timeout_s": (
        60.0,
        "Give up after this many seconds without completing (0 = never).",
        Range(0.0, 86_400.0, unit="s"),
    ),
    "fast_decode": (
        True,
        "Subscribe raw (CDR bytes) and decode with ads_rca.contract.cdr_decode instead of "
        "deserialising into rclpy message objects.",
    ),
}


class TopicSummary(Node):
    """Subscribes to every contract topic and records what arrives."""

    def __init__(self) -> None:
        super().__init__(
            "topic_summary", parameter_overrides=command_line_overrides("topic_summary")
        )
        values = declare_node_parameters(self, PARAMETERS)
        namespace = str(values["topic_namespace"])
        self.timeout = float(values["timeout_s"])
        self.assembler = RunLogAssembler()
        self.skipped = SkippedMessages()
        self.first_arrival: float | None = None
        self.last_arrival: float | None = None
        self.names = topics.topic_names(namespace)
        self.fast_decode = bool(self.get_parameter("fast_decode").value)
        self.subs = [
            self.create_subscription(
                topics.message_types()[key],
                self.names[key],
                self._callback(key),
                topics.qos_profile(key, keep_all=True),
                raw=self.fast_decode,
            )
            for key in topics.ALL_TOPICS
        ]
        log_in_force(self, values)

    def _callback(self, key: str) -> Any:
        # Raw subscriptions hand over the CDR bytes: the assembler keeps them and decodes
        # them straight into model records, with no rclpy message objects on the way.
        add = self.assembler.add_raw if self.fast_decode else self.assembler.add

        def on_message(msg: Any) -> None:
            now = time.monotonic()
            if self.first_arrival is None:
                self.first_arrival = now
            self.last_arrival = now
            try:
                add(key, msg)
            except MalformedMessage as error:  # CdrError, JsonTextError, a bad frame marker
                line = self.skipped.note(self.names[key], error, now)
                if line is not None:
                    self.get_logger().warning(line)

        return on_message

    def counts(self) -> dict[str, Any]:
        """Per topic: full name, type, received and announced counts."""
        a = self.assembler
        rows = {}
        for key in topics.ALL_TOPICS:
            msg_type = topics.message_types()[key]
            rows[self.names[key]] = {
                "type": f"{msg_type.__module__.split('.')[0]}/{msg_type.__name__}",
                "received": a.received[key],
                "expected": a.expected[key] if key in (*topics.DATA_TOPICS, topics.CLOCK) else None,
            }
        elapsed = (
            self.last_arrival - self.first_arrival
            if self.first_arrival is not None and self.last_arrival is not None
            else 0.0
        )
        return {
            "topics": rows,
            "complete": a.complete(),
            "missing": a.missing(),
            "status": a.status,
            "frames": len([i for i in a.markers if i >= 0]),
            "elapsed_s": elapsed,
            "skipped": dict(self.skipped.counts),
        }

    def table(self) -> str:
        summary = self.counts()
        lines = [f"{'topic':<48} {'type':<40} {'received':>9} {'announced':>9}"]
        for name, row in summary["topics"].items():
            expected = "" if row["expected"] is None else str(row["expected"])
            lines.append(f"{name:<48} {row['type']:<40} {row['received']:>9} {expected:>9}")
        state = "complete" if summary["complete"] else f"INCOMPLETE, missing {summary['missing']}"
        lines.append(f"{summary['frames']} analysed frames, {state}")
        return "\n".join(lines)

    def write_outputs(self) -> None:
        summary_file = str(self.get_parameter("summary_file").value)
        if summary_file:
            path = Path(summary_file)
            path.parent.mkdir(parents=True, exist_ok=True)
            counts = to_strict(self.counts())  # strict JSON, NaN/inf named (docs/topics.md)
            path.write_bytes(orjson.dumps(counts, option=orjson.OPT_INDENT_2))
        if self.get_parameter("output_json").value:
            from ads_rca.sources.log.writer import write_run_log

            out = Path(str(self.get_parameter("output_dir").value))
            try:
                log = self.assembler.build()
            except ContractError as error:  # no metadata, or a document that describes none
                self.get_logger().error(f"cannot rebuild the log: {error}")
                return
            write_run_log(log, out)
            self.get_logger().info(f"rebuilt log written to {out}")


def main(args: list[str] | None = None) -> int:
    if not start_process("topic_summary", args):
        return 2
    node: TopicSummary | None = None
    code = 0
    try:
        try:
            node = TopicSummary()
        except AdsRcaError as error:
            get_logger("topic_summary").error(str(error))
            return 2
        executor = make_executor()
        executor.add_node(node)
        deadline = time.monotonic() + node.timeout if node.timeout > 0 else float("inf")
        while keep_running() and not node.assembler.complete():
            if time.monotonic() > deadline:
                node.get_logger().error(
                    f"timed out after {node.timeout} s; missing {node.assembler.missing()}"
                )
                code = 1
                break
            executor.spin_once(timeout_sec=0.05)
        if stop_requested():
            code = 130
    except (KeyboardInterrupt, ExternalShutdownException):
        code = 130
    finally:
        if node is not None:
            print(node.table(), flush=True)
            node.write_outputs()
            node.destroy_node()
        rclpy.try_shutdown()
        ignore_stop_signals()
    return code


if __name__ == "__main__":
    sys.exit(main())
