"""A running node's parameters: read-only at run time, ranges in their descriptors, and one
line at start saying the values in force.

``ros2 param set`` used to return success and change nothing (a node reads its parameters
once, at start). The parameters are now declared read-only: this test is the ``ros2 param``
tool's side, done with an rclpy client over real DDS against a real monitor process.
"""

from __future__ import annotations

import sys
from typing import Any

import pytest
from rosrun import wait_for

from ads_rca.ros.launcher import ManagedProcess, ros_args

pytestmark = pytest.mark.timeout(120)


def _call(node: Any, executor: Any, service_type: Any, name: str, request: Any) -> Any:
    client = node.create_client(service_type, name)
    assert client.wait_for_service(timeout_sec=20.0), f"no service {name}"
    future = client.call_async(request)
    executor.spin_until_future_complete(future, timeout_sec=20.0)
    assert future.done(), f"no answer from {name}"
    return future.result()


def test_a_running_monitor_refuses_parameter_sets_and_describes_its_ranges(ros_env: Any) -> None:
    import rclpy
    from rcl_interfaces.srv import DescribeParameters, GetParameters, SetParameters
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter

    params = {"topic_namespace": ros_env.namespace, "safety_margin": 0.8}
    argv = [sys.executable, "-m", "ads_rca.ros.monitor", "planning_monitor", *ros_args(params)]
    monitor = ManagedProcess("planning_monitor", argv, ros_env.env, echo=sys.stderr)
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        wait_for(lambda: "judging planning" in monitor.output, 30, "the monitor to start")
        node = rclpy.create_node("param_client", context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        request = SetParameters.Request(
            parameters=[
                Parameter("safety_margin", value=0.1).to_parameter_msg(),
                Parameter("stale_timeout_s", value=9.0).to_parameter_msg(),
            ]
        )
        results = _call(
            node, executor, SetParameters, "/planning_monitor/set_parameters", request
        ).results
        assert [(r.successful, r.reason) for r in results] == [
            (False, "Trying to set a read-only parameter: safety_margin."),
            (False, "Trying to set a read-only parameter: stale_timeout_s."),
        ]
        names = ["safety_margin", "stale_timeout_s", "effect_time_window", "semantics"]
        got = _call(
            node,
            executor,
            GetParameters,
            "/planning_monitor/get_parameters",
            GetParameters.Request(names=names),
        ).values
        assert [got[0].double_value, got[1].double_value, got[2].integer_value] == [0.8, 2.0, 20]
        assert got[3].string_value == "corrected"
        described = _call(
            node,
            executor,
            DescribeParameters,
            "/planning_monitor/describe_parameters",
            DescribeParameters.Request(names=names),
        ).descriptors
        assert all(d.read_only for d in described)
        margin, stale, window, semantics = described
        ranges = [
            (r.from_value, r.to_value)
            for r in (margin.floating_point_range[0], stale.floating_point_range[0])
        ]
        assert ranges == [(0.0, 100.0), (0.0, 3600.0)]
        assert (window.integer_range[0].from_value, window.integer_range[0].to_value) == (
            0,
            100_000,
        )
        assert margin.additional_constraints == "range [0, 100] m"
        assert margin.description.startswith("In corrected mode: clearance below which")
        assert window.description.startswith("In corrected mode: a lower bound on the window")
        assert semantics.additional_constraints == "one of reference or corrected"
        executor.shutdown()
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
        monitor.stop()
    in_force = [line for line in monitor.lines if "parameters in force" in line]
    assert len(in_force) == 1, monitor.output
    assert (
        "[planning_monitor]: parameters in force: semantics corrected; thresholds: "
        in (in_force[0])
    )
    assert "effect_time_window=20, window_s=1.0, perc_match_iou=0.5" in in_force[0]
    assert "safety_margin=0.8," in in_force[0]
    assert f"node: topic_namespace='{ros_env.namespace}'" in in_force[0]


def test_every_node_logs_its_parameters_once_at_start(ros_env: Any) -> None:
    """The four monitors of one ``monitors`` process: one line each, reference mode."""
    params = {"topic_namespace": ros_env.namespace, "semantics": "reference"}
    argv = [sys.executable, "-m", "ads_rca.ros.monitor", "monitors", *ros_args(params)]
    monitors = ManagedProcess("monitors", argv, ros_env.env, echo=sys.stderr)
    try:
        wait_for(lambda: "judging perception" in monitors.output, 30, "the monitors to start")
    finally:
        monitors.stop()
    in_force = [line for line in monitors.lines if "parameters in force" in line]
    expected = (
        "parameters in force: semantics reference; thresholds: effect_time_window=10, "
        "perc_score_threshold=0.5, pred_score_threshold=0.1, planning_toleration_future_step=3, "
        "planning_toleration=2.0, event_time_s=-1.0, event_decel=4.0, event_clearance=0.3, "
        "event_ttc_s=1.0; node: "
    )
    for name in (
        "perception_monitor",
        "prediction_monitor",
        "planning_monitor",
        "controller_monitor",
    ):
        mine = [line for line in in_force if f"[{name}]: " in line]
        assert len(mine) == 1 and f"[{name}]: {expected}" in mine[0], monitors.output
