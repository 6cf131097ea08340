"""Dragon Lake Parking (DLP) scenes synthesised from the documented schema.

No DLP trajectory file is public, so fixtures and the benchmark write their own:
``write_dlp_scene(folder, frames)`` writes ``DJI_0001_{scene,frames,agents,instances,
obstacles}.json`` in DLP's own layout (dicts keyed by sha1 tokens, linked lists through
``prev`` / ``next``, the right-handed local frame, headings in radians, full sizes), every
value worked out by hand, at 25 fps (0.04 s):

- car 1 drives along +x at 5 m/s from (10, 20), heading 0, for the whole scene: the
  longest-lived moving car, so the default ego;
- car 2 reverses: it faces +x (heading 0) but moves along −x at 2.5 m/s from (40, 30),
  from frame 5 to frame ``frames − 6``;
- a pedestrian walks along +y at 1 m/s from (25, 10), heading π/2, for the first half;
- ``extra_agents`` more cars drive along +x in lanes 4 m apart (the benchmark's crowd);
- one parked car (an obstacle) stands at (60, 5), heading π.

Files are written as streams, so a scene of a million instances never sits in memory.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

STEP_S = 0.04
STEM = "DJI_0001"


def token(key: str) -> str:
    """A DLP token: the sha1 of a description, as the dataset's generator makes them."""
    return hashlib.sha1(key.encode("utf-8")).hexdigest()


@dataclass(frozen=True)
class Agent:
    """One moving agent: its kind, full size, first and last frame, start and velocity."""

    number: int
    kind: str
    size: tuple[float, float]
    first: int
    last: int
    start: tuple[float, float]
    velocity: tuple[float, float]
    heading: float

    @property
    def token(self) -> str:
        return token(f"{STEM}_agent_{self.number}")

    def instance(self, frame: int) -> str:
        return token(f"{STEM}_instance_{frame}_{self.number}")

    def position(self, frame: int) -> tuple[float, float]:
        t = (frame - self.first) * STEP_S
        return self.start[0] + self.velocity[0] * t, self.start[1] + self.velocity[1] * t


def scene_agents(frames: int, extra_agents: int = 0) -> list[Agent]:
    agents = [
        Agent(1, "Car", (4.7, 1.9), 0, frames - 1, (10.0, 20.0), (5.0, 0.0), 0.0),
        Agent(2, "Car", (4.5, 1.8), 5, frames - 6, (40.0, 30.0), (-2.5, 0.0), 0.0),
        Agent(3, "Pedestrian", (0.83, 0.83), 0, frames // 2, (25.0, 10.0), (0.0, 1.0), math.pi / 2),
    ]
    agents += [
        Agent(4 + n, "Car", (4.5, 1.8), 0, frames - 1, (0.0, 40.0 + 4 * n), (3.0, 0.0), 0.0)
        for n in range(extra_agents)
    ]
    return agents


def frame_token(frame: int) -> str:
    return token(f"{STEM}_frame_{frame}")


def write_dlp_scene(folder: str | Path, frames: int = 50, extra_agents: int = 0) -> Path:
    """Write one scene (see the module docstring); returns its ``_scene.json`` path."""
    root = Path(folder)
    root.mkdir(parents=True, exist_ok=True)
    agents = scene_agents(frames, extra_agents)
    scene_token = token(f"{STEM}_scene")
    obstacle = {
        "obstacle_token": token(f"{STEM}_obstacle_1"),
        "scene_token": scene_token,
        "type": "Car",
        "size": [4.6, 2.0],
        "coords": [60.0, 5.0],
        "heading": math.pi,
    }
    scene = {
        "scene_token": scene_token,
        "filename": STEM,
        "timestamp": "2020-09-27 09:00:00",
        "first_frame": frame_token(0),
        "last_frame": frame_token(frames - 1),
        "agents": [a.token for a in agents],
        "obstacles": [obstacle["obstacle_token"]],
    }
    (root / f"{STEM}_scene.json").write_text(json.dumps(scene))
    (root / f"{STEM}_obstacles.json").write_text(json.dumps({obstacle["obstacle_token"]: obstacle}))
    (root / f"{STEM}_agents.json").write_text(
        json.dumps(
            {
                a.token: {
                    "agent_token": a.token,
                    "scene_token": scene_token,
                    "type": a.kind,
                    "size": list(a.size),
                    "first_instance": a.instance(a.first),
                    "last_instance": a.instance(a.last),
                }
                for a in agents
            }
        )
    )
    with (root / f"{STEM}_frames.json").open("w") as out:
        _write_object(out, _frames(frames, agents, scene_token))
    with (root / f"{STEM}_instances.json").open("w") as out:
        _write_object(out, _instances(frames, agents))
    return root / f"{STEM}_scene.json"


def _frames(frames: int, agents: list[Agent], scene_token: str) -> Iterator[tuple[str, Any]]:
    for frame in range(frames):
        yield (
            frame_token(frame),
            {
                "frame_token": frame_token(frame),
                "scene_token": scene_token,
                "timestamp": round(frame * STEP_S, 2),
                "prev": frame_token(frame - 1) if frame > 0 else "",
                "next": frame_token(frame + 1) if frame < frames - 1 else "",
                "instances": [a.instance(frame) for a in agents if a.first <= frame <= a.last],
            },
        )


def _instances(frames: int, agents: list[Agent]) -> Iterator[tuple[str, Any]]:
    for agent in agents:
        speed = math.hypot(*agent.velocity)
        for frame in range(agent.first, agent.last + 1):
            x, y = agent.position(frame)
            yield (
                agent.instance(frame),
                {
                    "instance_token": agent.instance(frame),
                    "agent_token": agent.token,
                    "frame_token": frame_token(frame),
                    "coords": [x, y],
                    "heading": agent.heading,
                    "speed": speed,
                    "acceleration": [0.0, 0.0],
                    "mode": "",
                    "prev": agent.instance(frame - 1) if frame > agent.first else "",
                    "next": agent.instance(frame + 1) if frame < agent.last else "",
                },
            )


def _write_object(out: IO[str], members: Iterator[tuple[str, Any]]) -> None:
    out.write("{")
    for n, (key, value) in enumerate(members):
        out.write(("" if n == 0 else ", ") + json.dumps(key) + ": " + json.dumps(value))
    out.write("}")
