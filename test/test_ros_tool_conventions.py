"""What ROS tools expect of our outputs: diagnostics keyed by name, plottable metrics, camera.

- ``/diagnostics``: one status per module per array (rqt_robot_monitor, the
  diagnostic_aggregator and Foxglove key statuses by name and keep only the last);
- ``metrics/<module>/values``: the JSON metrics as numbers with labels, equal frame by frame
  to the JSON, in a recorded MCAP read back with mcap-ros2-support;
- the camera: its static transform and CameraInfo, latched, built from the run metadata.
"""

from __future__ import annotations

from ads_rca.live.results import LiveResult
from ads_rca.oracles.base import OracleResult
from ads_rca.ros import diagnostics as diag


def _result(index: int, failed: bool, metrics: dict[str, object] | None = None) -> LiveResult:
    oracle = OracleResult("perception", 50 * index, failed, metrics or {}, {}, (), None)
    return LiveResult(index=index, result=oracle, frame=index, run="r1")


def test_a_judged_batch_is_one_status_for_its_latest_frame() -> None:
    batch = [_result(3, False), _result(4, True), _result(5, True), _result(6, False)]
    status = diag.batch_status(batch, "corrected", "hw")
    values = dict(status.values)
    assert status.name == "ads_rca/perception"
    assert status.level == diag.OK  # the latest frame passed
    assert status.message == "frame 6: ok (2 of 4 frames since the last status failed)"
    assert values["frame"] == "6" and values["index"] == "6" and values["run"] == "r1"
    assert values["judged_since_last"] == "4" and values["failed_since_last"] == "2"
    failing = diag.batch_status(batch[:2], "corrected", "hw")
    assert failing.level == diag.ERROR
    assert failing.message == "frame 4: perception failed"
    assert dict(failing.values)["failed_since_last"] == "1"
    # The encoded array holds that one status (what the aggregator's raw reader sees).
    assert diag.status_runs(diag.encode_array(0, [status])) == [("ads_rca/perception", "r1")]
