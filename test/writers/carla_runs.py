"""CARLA experiment-client run folders synthesised from the documented schemas.

No real run of the client is public, so the fixtures, the demo and the benchmarks write
their own: ``write_carla_run(folder, schema)`` makes a straight-road scene whose every
figure can be worked out by hand. The ego drives east (CARLA +x) at 10 m/s from the origin;
a Tesla Model 3 (id 101) starts ``lead_gap_m`` ahead at 5 m/s in the same lane; an adult
pedestrian (202) crosses 20 m ahead at 2 m/s; a vehicle of a blueprint the table does not
know (505) is parked 20 m to the right; a traffic light (303) and a sensor (404) are listed
too, as the client lists every actor within 50 m. ``schema``: ``v0`` (the documented
telemetry), ``v0.2`` (``speed_fd`` / ``speed_actor``, actors' finite-difference speeds,
traffic lights), ``csv`` (``telemetry.csv`` only, v0 columns). ``plan.json`` holds the
ego's path, shifted ``plan_offset_m`` to its left, and ``events.json`` one cut-in at 1.0 s.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

EGO_SPEED = 10.0
LEAD_SPEED = 5.0
WALKER_SPEED = 2.0
EGO_BLUEPRINT = "vehicle.lincoln.mkz_2020"
SCHEMAS = ("v0", "v0.2", "csv")


def _ego(t: float, schema: str) -> dict[str, Any]:
    ego: dict[str, Any] = {
        "position": {"x": EGO_SPEED * t, "y": 0.0, "z": 0.5},
        "velocity": {"vx": EGO_SPEED, "vy": 0.0, "vz": 0.0},
        "acceleration": {"ax": 0.0, "ay": 0.0, "az": 0.0},
        "angular_velocity": {"roll_rate": 0.0, "pitch_rate": 0.0, "yaw_rate": 0.0},
        "orientation": {"roll": 0.0, "pitch": 0.0, "yaw": 0.0},
        "control": {"throttle": 0.5, "brake": 0.0, "steer": 0.0},
    }
    if schema == "v0.2":
        ego.update(speed_actor=0.0, speed_fd=EGO_SPEED)  # teleported: CARLA's velocity is 0
    else:
        ego["speed"] = EGO_SPEED
    return ego


def _actor(
    actor_id: int,
    kind: str,
    type_id: str,
    xy: tuple[float, float],
    yaw: float,
    speed: float,
    schema: str,
) -> dict[str, Any]:
    actor: dict[str, Any] = {
        "id": actor_id,
        "type": kind,
        "type_id": type_id,
        "role_name": "",
        "position": {"x": xy[0], "y": xy[1], "z": 0.5},
        "rotation": {"roll": 0.0, "pitch": 0.0, "yaw": yaw},
        "distance_to_ego": 0.0,
    }
    if kind in ("vehicle", "walker"):
        if schema == "v0.2":
            actor.update(speed=speed, speed_fd=speed, speed_actor=speed)
        else:
            actor["speed"] = speed
    return actor


def _actors(t: float, lead_gap_m: float, schema: str) -> list[dict[str, Any]]:
    return [
        _actor(
            101,
            "vehicle",
            "vehicle.tesla.model3",
            (lead_gap_m + LEAD_SPEED * t, 0.0),
            0.0,
            LEAD_SPEED,
            schema,
        ),
        _actor(
            202,
            "walker",
            "walker.pedestrian.0001",
            (20.0, 8.0 - WALKER_SPEED * t),
            -90.0,
            WALKER_SPEED,
            schema,
        ),
        _actor(303, "traffic_light", "traffic.traffic_light", (40.0, 5.0), 0.0, 0.0, schema),
        _actor(404, "unknown", "sensor.camera.rgb", (0.0, 0.0), 0.0, 0.0, schema),
        _actor(505, "vehicle", "vehicle.custom.prototype", (10.0, 20.0), 0.0, 0.0, schema),
    ]


def write_carla_run(
    folder: str | Path,
    schema: str = "v0",
    ticks: int = 40,
    fps: int = 20,
    lead_gap_m: float = 30.0,
    plan_offset_m: float = 0.0,
) -> Path:
    """Write one run folder (see the module docstring); returns it."""
    if schema not in SCHEMAS:
        raise ValueError(f"schema {schema!r}: expected one of {', '.join(SCHEMAS)}")
    root = Path(folder)
    root.mkdir(parents=True, exist_ok=True)
    times = [n / fps for n in range(ticks)]
    facts = {
        "scenario_id": "lane_change_cut_in",
        "scenario_config": "scenario.yaml",
        "map": "Town05",
        "seed": 7,
        "fps": fps,
        "duration": ticks / fps,
        "fixed_delta_seconds": 1.0 / fps,
        "sync_mode": True,
        "server_version": "0.9.15",
        "client_version": "0.9.15",
    }
    (root / "run_metadata.json").write_text(json.dumps(facts, indent=2))
    (root / "scenario.yaml").write_text(
        f"id: lane_change_cut_in\nmap: Town05\nfps: {fps}\nego_vehicle: {EGO_BLUEPRINT}\n"
    )
    if schema == "csv":
        _write_csv(root / "telemetry.csv", times)
    else:
        _write_json(root / "telemetry.json", times, fps, lead_gap_m, schema)
    event = {
        "t": 1.0,
        "t_event": 1.0,
        "t_voice_start": 0.0,
        "t_robot_precue": 0.0,
        "type": "vehicle_cut_in",
        "decision_text": "Brake",
        "reason_text": "Vehicle cutting in ahead",
        "robot_precue_t": 0.0,
        "audio_id": "vehicle_cut_in_00",
    }
    (root / "events.json").write_text(json.dumps({"events": [event]}, indent=2))
    trajectory = [
        {"t": t, "x": EGO_SPEED * t, "y": -plan_offset_m, "yaw": 0.0, "v": EGO_SPEED, "a": 0.0}
        for t in [n / fps for n in range(ticks + 20)]
    ]
    plan = {
        "version": "0.2",
        "episode_id": "lane_change_cut_in",
        "town": "Town05",
        "seed": 7,
        "dt": 1.0 / fps,
        "duration": ticks / fps,
        "actors": [
            {
                "id": "ego",
                "kind": "vehicle",
                "role": "ego",
                "blueprint": EGO_BLUEPRINT,
                "controller": "teleport",
                "trajectory": trajectory,
            }
        ],
        "events_plan": [],
    }
    (root / "plan.json").write_text(json.dumps(plan))
    return root


def _write_json(path: Path, times: list[float], fps: int, lead_gap_m: float, schema: str) -> None:
    metadata: dict[str, Any] = {
        "fps": fps,
        "total_frames": len(times),
        "coordinate_system": "SAE_J670",
        "units": {"position": "meters", "velocity": "m/s", "angles": "degrees"},
    }
    if schema == "v0.2":
        metadata.update(
            schema_version="0.2",
            position_frame="CARLA_WORLD",
            vehicle_frame="SAE_J670",
            dt=1.0 / fps,
        )
    frames = []
    for n, t in enumerate(times):
        frame: dict[str, Any] = {
            "frame": n,
            "t_sim": round(t, 3),
            "t_world": round(t, 3),
            "dt": 1.0 / fps,
            "ego": _ego(t, schema),
            "actors": _actors(t, lead_gap_m, schema),
        }
        if schema == "v0.2":
            frame["traffic_lights"] = [
                {
                    "id": 303,
                    "state": "Red",
                    "position": {"x": 40.0, "y": 5.0, "z": 0.0},
                    "group_ids": [303],
                    "timing": {"red": 10.0, "elapsed_time": t},
                }
            ]
        frames.append(frame)
    path.write_text(json.dumps({"metadata": metadata, "frames": frames}))


def _write_csv(path: Path, times: list[float]) -> None:
    header = [
        "frame",
        "t_sim",
        "t_world",
        "dt",
        "world_x",
        "world_y",
        "world_z",
        "vx",
        "vy",
        "vz",
        "ax",
        "ay",
        "az",
        "roll_rate",
        "pitch_rate",
        "yaw_rate",
        "roll",
        "pitch",
        "yaw",
        "speed",
        "throttle",
        "brake",
        "steer",
    ]
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(header)
        for n, t in enumerate(times):
            writer.writerow(
                [
                    n,
                    round(t, 3),
                    round(t, 3),
                    0.05,
                    EGO_SPEED * t,
                    0.0,
                    0.5,
                    EGO_SPEED,
                    0.0,
                    0.0,
                    0.0,
                    0.0,
                    0.0,
                    0.0,
                    0.0,
                    0.0,
                    0.0,
                    0.0,
                    0.0,
                    EGO_SPEED,
                    0.5,
                    0.0,
                    0.0,
                ]
            )
