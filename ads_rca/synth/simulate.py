"""The closed loop: world → camera → detector → tracker → predictor → planner → controller.

One call runs a scene for one fault and returns the run log (a running log folder's content) plus
what happened. Random numbers come from a generator seeded by the scene seed only and are
drawn identically whatever the fault, so a faulty run equals its twin up to the onset. The
3-D perception output (``detections_3d``, ``tracks_3d``) draws its noise from a second
generator of its own, and ``controls`` records each frame's command to the controller.

The noise level (:class:`~ads_rca.synth.noise.Noise`) scales every perception σ. Its
localisation error e_t is a pure translation of the stack's world frame, which changes no
relative geometry: the loop (perception, prediction, planning, control) runs on the true pose
exactly as without it, and e_t is added only to what the stack records in its own frame: the
pose, the plan, the 3-D detections and tracks; ground-truth predictions are expressed relative
to the localised pose. Ground truth (actors, also the ego's) and image boxes keep no e_t, and
the raw predictions' body-frame offsets are unchanged (the stack's positions and its pose shift
together).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ads_rca.model import (
    Actors,
    Boxes,
    ControlCommand,
    EgoPose,
    Objects3D,
    Plan,
    Predictions,
    RunLog,
    RunMetadata,
    Track,
)
from ads_rca.synth.camera import project_boxes
from ads_rca.synth.control import Controller
from ads_rca.synth.faults import BRAKE_GAIN, FaultSpec
from ads_rca.synth.geometry import FloatArray, sat_gap, to_body, to_world
from ads_rca.synth.noise import DEFAULT_NOISE, Noise
from ads_rca.synth.perception import Detector, Tracker
from ads_rca.synth.perception3d import Misperception, Output3D
from ads_rca.synth.planning import Planner
from ads_rca.synth.prediction import predict_positions, state_from_history, wrong_model
from ads_rca.synth.steering import WHEELBASE, PathFollower, VehicleState, start_state, step
from ads_rca.synth.world import PAD, Scene

TPF_MS = 50
CAMERA_LOC = (1.3, 0.0, 1.8)
PREDICTION_ON_TRUTH_RANGE = 80.0


@dataclass
class SimResult:
    """A finished run: the log, the collision (frame, actor row; -1 if none), the reaction."""

    log: RunLog
    collision_frame: int
    collided_row: int
    reaction_frame: int


def _f32(a: FloatArray) -> FloatArray:
    """Values as the simulator's float32 state, like CARLA's actor records."""
    return a.astype(np.float32).astype(np.float64)


def simulate(
    scene: Scene,
    fault: FaultSpec,
    seed: int,
    horizon: int = 30,
    noise: Noise = DEFAULT_NOISE,
    follower: PathFollower | None = None,
) -> SimResult:
    """Run ``scene`` in closed loop with ``fault`` at ``noise`` until a collision or the last
    frame. ``follower``: the ego steers along its path with these lateral dynamics (None:
    it rides the path exactly, as in our synthesised worlds)."""
    n = len(scene.actor_ids)
    rng = np.random.default_rng([seed, 7])
    detector = Detector(rng, n, never_miss=scene.partner, noise=noise)
    tracker = Tracker(n, first_id=1000 + int(rng.integers(0, 9000)))
    planner = Planner(scene.path, scene.ego_extent[:2], scene.desired_speed, horizon)
    controller = Controller()
    pred_keys = tuple(str(k) for k in range(horizon))
    plan_keys = tuple(str(i) for i in range(horizon + 1))
    labels: list[Mapping[str, Any]] = [{"label": k} for k in scene.kinds]
    all_ids = (scene.ego_id, *scene.actor_ids)
    extent_all = np.vstack([scene.ego_extent[None, :], scene.extent])
    half = scene.extent[:, :2]
    stale = (np.zeros(2), np.zeros(2))
    if scene.partner >= 0:
        t = scene.trigger_frame + PAD
        p_t, p_b = scene.xy[t, scene.partner], scene.xy[t - 1, scene.partner]
        stale = (p_t, (p_t - p_b) / 0.05)
    misperception = Misperception(scene, stale_velocity=stale[1], stale_position=stale[0])
    output_3d = Output3D(np.random.default_rng([seed, 11]), scene.kinds, noise)
    localisation = noise.localisation_error(seed, scene.frames)

    log = RunLog(metadata=RunMetadata(TPF_MS, CAMERA_LOC, -1, 0), frames=())
    s, v = 0.0, scene.ego_speed
    vehicle = None if follower is None else start_state(scene.path, s)
    collision, collided, reaction = -1, -1, -1
    frames: list[int] = []
    last = scene.frames
    for f in range(1, scene.frames + 1):
        ts = f * TPF_MS
        i = f + PAD
        xy, yaw = scene.xy[i], scene.yaw[i]
        if vehicle is None:
            pose_xy, pose_yaw_arr = scene.path.at(np.asarray(s))
            pose_yaw = float(pose_yaw_arr)
        else:
            pose_xy, pose_yaw = vehicle.xy, vehicle.yaw
        # Where the stack believes it is (the true pose without localisation error).
        offset = None if localisation is None else localisation[f - 1]
        localised = pose_xy if offset is None else pose_xy + offset
        gaps = sat_gap(pose_xy, np.asarray(pose_yaw), scene.ego_extent[:2], xy, yaw, half)
        if gaps.min() < 0.0:
            collision, collided = f, int(np.argmin(gaps))

        # Camera and perception.
        gt, in_view = project_boxes(pose_xy, pose_yaw, CAMERA_LOC, xy, yaw, scene.extent)
        suppressed = np.zeros(n, dtype=bool)
        variant = fault.perceived(f)
        if variant == "missed" and scene.partner >= 0:
            suppressed[scene.partner] = True
        det = detector.detect(gt, in_view, xy, yaw, pose_xy, suppressed, scene.extent)
        det = misperception.apply(det, variant, i, s, pose_xy, v)
        tracker.update(det)

        # Prediction from tracks (raw) and from ground-truth history (on truth).
        rows = tracker.published()
        pos, vel, acc = tracker.pos[rows], tracker.vel[rows], tracker.acc[rows]
        faulty_prediction = fault.active("prediction", f)
        if faulty_prediction:
            pos, vel, acc = _inject(scene, rows, pos, vel, acc, stale)
        raw_world = predict_positions(pos, vel, acc, horizon)
        raw_off = to_body(raw_world, pose_xy, pose_yaw)

        near = np.flatnonzero(np.hypot(*(xy - pose_xy).T) < PREDICTION_ON_TRUTH_RANGE)
        g_pos, g_vel, g_acc = state_from_history(scene.xy[i - 2 : i + 1, near])
        if faulty_prediction:
            g_pos, g_vel, g_acc = _inject(scene, near, g_pos, g_vel, g_acc, stale)
        on_truth_off = to_body(predict_positions(g_pos, g_vel, g_acc, horizon), localised, pose_yaw)

        # Planning from the published raw predictions only.
        keep = np.ones(rows.size, dtype=bool)
        if fault.active("planning", f):
            keep = rows != scene.partner
        seen = to_world(raw_off[keep], pose_xy, pose_yaw)
        shapes = tracker.extent[rows][keep, :2]
        result = planner.plan(
            s, v, pose_xy, pose_yaw, seen, pos[keep], tracker.yaw[rows][keep], shapes
        )
        if (
            reaction < 0
            and f >= scene.trigger_frame
            and result.binding >= 0
            and rows[keep][result.binding] == scene.partner
        ):
            reaction = f

        # Record this frame.
        frames.append(ts)
        log.pose[ts] = EgoPose(
            float(localised[0]),
            float(localised[1]),
            0.0,
            0.0,
            0.0,
            float(np.degrees(pose_yaw)),
            float(v),
        )
        loc = np.zeros((n + 1, 3))
        loc[0, :2] = pose_xy
        loc[1:, :2] = xy
        rot = np.zeros((n + 1, 3))
        rot[0, 2] = np.degrees(pose_yaw)
        rot[1:, 2] = np.degrees(yaw)
        log.actors[ts] = Actors(all_ids, _f32(loc), _f32(rot), extent_all)
        log.bboxes[ts] = Boxes(det.ids, det.corners, tuple(labels[r] for r in det.rows))
        view = np.flatnonzero(in_view)
        log.bboxes_gt[ts] = Boxes(
            tuple(scene.actor_ids[r] for r in view), gt[view], tuple(labels[r] for r in view)
        )
        log.predictions[ts] = _tracks([str(t) for t in tracker.track_id[rows]], raw_off, pred_keys)
        log.predictions_with_perception[ts] = _tracks(
            [scene.actor_ids[r] for r in near], on_truth_off, pred_keys
        )
        log.waypoints[ts] = Plan(plan_keys, _shift(result.xy, offset), result.speed.copy())
        log.detections_3d[ts] = _placed(output_3d.detections(det, pose_xy), offset)
        log.tracks_3d[ts] = _placed(output_3d.tracks(tracker, rows), offset)
        log.controls[ts] = _command(scene, s, v, float(result.speed[1]), vehicle)
        if collision >= 0:
            last = f
            break

        # Control.
        controller.brake_gain = BRAKE_GAIN if fault.active("controller", f) else 1.0
        s_next, v_next = controller.step(s, v, float(result.speed[1]))
        if vehicle is not None and follower is not None:
            vehicle = step(follower, scene.path, vehicle, s_next - s, v, TPF_MS / 1000.0)
            s_next = vehicle.s
        s, v = s_next, v_next

    log.frames = tuple(frames)
    log.metadata = RunMetadata(TPF_MS, CAMERA_LOC, collision, last)
    return SimResult(log, collision, collided, reaction)


def _command(
    scene: Scene, s: float, v: float, target: float, vehicle: VehicleState | None
) -> ControlCommand:
    """The command to the controller: the plan's next speed, the acceleration to reach it in
    one frame, and the steering angle (CARLA sign: + turns right): the path follower's, else
    that of the path's curvature."""
    if vehicle is not None:
        steer = float(np.degrees(vehicle.steer))
    else:
        _, yaw = scene.path.at(np.array([s - 0.5, s + 0.5]))
        curvature = float(yaw[1] - yaw[0])  # rad per metre (1 m apart)
        steer = float(np.degrees(np.arctan(WHEELBASE * curvature)))
    return ControlCommand(steer=steer, acceleration=(target - v) / TPF_MS * 1000.0, speed=target)


def _inject(
    scene: Scene,
    rows: np.ndarray,
    pos: FloatArray,
    vel: FloatArray,
    acc: FloatArray,
    stale: tuple[FloatArray, FloatArray],
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Replace the partner's motion state by the scene's optimistic wrong model."""
    hit = np.flatnonzero(rows == scene.partner)
    if hit.size == 0:
        return pos, vel, acc
    pos, vel, acc = pos.copy(), vel.copy(), acc.copy()
    p, v, a = wrong_model(
        scene.prediction_fault_model, pos[hit], vel[hit], acc[hit], *stale, scene.road_direction
    )
    pos[hit], vel[hit], acc[hit] = p, v, a
    return pos, vel, acc


def _shift(xy: FloatArray, offset: FloatArray | None) -> FloatArray:
    """World points ``xy`` (N, 2) as the stack records them: moved by its localisation error."""
    return xy if offset is None else xy + offset


def _placed(objects: Objects3D, offset: FloatArray | None) -> Objects3D:
    """3-D objects perceived relative to the ego, placed with the localised pose."""
    if offset is None:
        return objects
    location = objects.location.copy()
    location[:, :2] += offset
    return replace(objects, location=location)


def _tracks(ids: list[str], offsets: FloatArray, keys: tuple[str, ...]) -> Predictions:
    full = np.zeros((*offsets.shape[:2], 3))
    full[..., :2] = offsets
    return {obstacle: Track(keys, full[m]) for m, obstacle in enumerate(ids)}
