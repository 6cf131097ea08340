"""Fair runs on SUMO scenes, by the synthesiser's rules, written as ``ads-rca synth`` writes.

For a family and a seed, attempt after attempt (each a new draw of the family's parameters
and SUMO seed), a scene is recorded and accepted only as :func:`ads_rca.synth.synthesise_run`
accepts one: the fault-free twin must not crash and must react to the partner (its planner
brakes for it at or after the trigger), and each of the four module faults, injected from
``onset_for(twin reaction)``, must crash into the partner. A perception variant takes the
first accepted scene on which it crashes into the partner (its label's ``attempt`` says
which); ``crossing`` × ``perception:shrunk`` is refused as the synthesiser refuses
``pedestrian_crossing`` × ``shrunk``.

Before the fairness check the scene is replayed (:data:`PASSES` runs at most): SUMO runs
again with the same commands while its ego is moved along where our fault-free twin drove,
so the traffic (followers, lane changers, LC2013's gap acceptance) reacts to our ego rather
than to SUMO's own; the scene is rebuilt from that run and the twin run again, until its
track stops changing. Faulty runs then replay that world open-loop.

Each run is a log folder written by :func:`ads_rca.sources.log.writer.write_run_log` (what
``ads-rca synth OUT`` writes), with ``metadata.json["synthesis"]`` naming the family, fault,
seed, attempt, onset, twin reaction and ``"world": "sumo <version>"``.
"""

from __future__ import annotations

import hashlib
import json
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ads_rca.model import RunLog
from ads_rca.sources.log.writer import write_run_log
from ads_rca.synth import FAULTS, VARIANT_FAULTS, canonical_fault
from ads_rca.synth.faults import NO_FAULT, FaultSpec, onset_for
from ads_rca.synth.noise import Noise
from ads_rca.synth.simulate import SimResult, simulate
from ads_rca.synth.steering import PathFollower
from sumo_world import families, record
from sumo_world.env import CACHE, SUMO_VERSION, Sumo, client
from sumo_world.scene import Built, build_scene, centres

LOGS = CACHE / "sumo-logs"
MAX_ATTEMPTS = 10
PASSES = 4
#: A timed partner is moved when it reaches its mark more than this off (s).
TIMED_S = 0.1
DEFAULT_FRAMES = 200
DEFAULT_HORIZON = 30
CONVERGED_M = 0.05
#: The ego's lateral dynamics: it steers along SUMO's lane centre line as a vehicle does
#: (pure pursuit on a kinematic bicycle), so a curve's entry shows a path follower's error.
FOLLOWER = PathFollower()
INAPPLICABLE = {
    ("crossing", "perception:shrunk"): (
        "a pedestrian's 0.5 m box shrunk recedes 0.35 m, less than the planner's 1 m margin"
    ),
}


def code_digest() -> str:
    """A hash of this package's sources: a cached set is rebuilt when the code changes."""
    digest = hashlib.sha256()
    for source in sorted(Path(__file__).parent.glob("*.py")):
        digest.update(source.read_bytes())
    return digest.hexdigest()[:10]


def cache_key(frames: int, horizon: int, noise: float) -> str:
    return f"sumo{SUMO_VERSION}-f{frames}-h{horizon}-k{noise:g}-{code_digest()}"


@dataclass
class Outcome:
    """One family × fault × seed: the log folder written, or why there is none."""

    family: str
    fault: str
    seed: int
    folder: Path | None
    refused: str = ""
    label: dict[str, Any] = field(default_factory=dict)


@dataclass
class World:
    """A recorded scene and its fault-free twin."""

    built: Built
    twin: SimResult
    setup: families.Setup
    passes: int
    timing_error_s: float = 0.0  # how much later the partner should have come (timed families)


def record_world(
    sumo: Sumo, family: str, seed: int, attempt: int, frames: int, horizon: int, noise: Noise
) -> World:
    """Record one attempt's scene, replayed until our twin's track settles."""
    _, sumolib = client(sumo)
    rng = np.random.default_rng([seed, attempt, 0x5D30])
    setup = families.build(family, rng)
    state = rng.bit_generator.state
    net = setup.net.build(sumo)
    sumo_seed = (seed * 1009 + attempt * 7919) % (1 << 31)
    sub_seed = seed * 1000 + attempt

    def scene_of(rec: record.Recording, first: Built | None) -> Built:
        again = np.random.default_rng()
        again.bit_generator.state = state
        if first is None:
            return build_scene(rec, again, frames, f"sumo:{family}", sumolib)
        return build_scene(rec, again, frames, f"sumo:{family}", sumolib, first)

    director = setup.director
    rec = record.run(sumo, net, director, sumo_seed, setup.options)
    first_event = rec.event
    built = original = scene_of(rec, None)
    previous: dict[int, tuple[float, float, float]] | None = None
    passes = 1
    while True:
        twin = simulate(built.scene, NO_FAULT, sub_seed, horizon, noise, FOLLOWER)
        track = _track(built, twin)
        shift = 0.0
        if director.timed:
            shift = _timing_error(built, rec, director, sumolib, sub_seed, horizon, noise)
        settled = previous is not None and _settled(previous, track)
        if (settled and abs(shift) < TIMED_S) or passes == PASSES:
            break
        if abs(shift) >= TIMED_S:
            director.shift(shift)
        replay = record.Replay(list(director.actions), first_event, track, director.observed)
        rec = record.run(sumo, net, director, sumo_seed, setup.options, replay)
        built = scene_of(rec, original)
        previous = track
        passes += 1
    return World(built, twin, setup, passes, shift)


def _timing_error(
    built: Built,
    rec: record.Recording,
    director: record.Director,
    sumolib: Any,
    sub_seed: int,
    horizon: int,
    noise: Noise,
) -> float:
    """How much later (s) the partner should reach its mark: our ego, blind to the partner
    (a planning fault from frame 1), reaches its own mark at some step; the partner should
    reach its mark ``director.late`` s after that."""
    ego_mark, partner_mark = director.marks(sumolib)
    scene = built.scene
    blind = simulate(scene, FaultSpec("planning", 1), sub_seed, horizon, noise, FOLLOWER)
    target = built.to_scene(ego_mark)
    arrival = None
    for ts in blind.log.frames:
        actors = blind.log.actors[ts]
        here = actors.location[0, :2].astype(np.float64)
        yaw = np.radians(float(actors.rotation[0, 2]))
        ahead = float((target - here) @ np.array([np.cos(yaw), np.sin(yaw)]))
        if ahead <= 0.0:
            arrival = ts / 50.0
            break
    if arrival is None:
        last = blind.log.frames[-1]
        speed = blind.log.pose[last].speed
        if speed < 1.0:
            return 0.0
        arrival = last / 50.0 + max(ahead, 0.0) / speed / record.STEP_S
    column = rec.ids.index(rec.event.partner)
    cols = np.array([column])
    centre = centres(rec, rec.front[:, cols], rec.angle[:, cols], cols)[:, 0]
    distance = np.hypot(*(centre - partner_mark).T)
    if not np.isfinite(distance).any() or np.nanmin(distance) > 3.0:
        return 0.0
    partner_step = rec.first_step + int(np.nanargmin(distance))
    ego_step = built.first + arrival
    return float((ego_step - partner_step) * record.STEP_S + director.late)


def _track(built: Built, run: SimResult) -> dict[int, tuple[float, float, float]]:
    """Where our ego drove, per SUMO step, as SUMO's front bumper (x, y, angle)."""
    track = {}
    for ts in run.log.frames:
        actors = run.log.actors[ts]
        frame = ts // 50
        track[built.first + frame] = built.to_sumo(
            actors.location[0, :2].astype(np.float64), float(actors.rotation[0, 2])
        )
    return track


def _settled(
    old: dict[int, tuple[float, float, float]], new: dict[int, tuple[float, float, float]]
) -> bool:
    if old.keys() != new.keys():
        return False
    return all(np.hypot(old[k][0] - new[k][0], old[k][1] - new[k][1]) < CONVERGED_M for k in old)


def judge(
    sumo: Sumo, family: str, seed: int, attempt: int, frames: int, horizon: int, noise: Noise
) -> tuple[World, dict[str, SimResult], int] | str:
    """An attempt's world, its twin and module-fault runs and the onset, if it is accepted;
    else why not."""
    try:
        world = record_world(sumo, family, seed, attempt, frames, horizon, noise)
    except record.Refused as error:
        return str(error)
    scene, twin = world.built.scene, world.twin
    if twin.collision_frame >= 0:
        return f"the twin crashed (actor row {twin.collided_row})"
    if twin.reaction_frame < 0:
        return "the twin never braked for the partner"
    onset = onset_for(twin.reaction_frame)
    sub_seed = seed * 1000 + attempt
    runs: dict[str, SimResult] = {"none": twin}
    for module in FAULTS[1:]:
        run = simulate(scene, FaultSpec(module, onset), sub_seed, horizon, noise, FOLLOWER)
        runs[module] = run
        if run.collision_frame < 0 or run.collided_row != scene.partner:
            return f"the {module} fault did not crash into the partner"
    return world, runs, onset


def build_seed(
    sumo: Sumo,
    family: str,
    seed: int,
    faults: list[str],
    root: Path,
    noise: Noise,
    frames: int = DEFAULT_FRAMES,
    horizon: int = DEFAULT_HORIZON,
) -> list[Outcome]:
    """Every fault of ``faults`` on ``family``'s scene for ``seed``, written under ``root``
    (a cached outcome is read back, not rebuilt)."""
    outcomes: dict[str, Outcome] = {}
    pending: list[str] = []
    for fault in faults:
        cached = _cached(root, family, seed, fault)
        if cached is not None:
            outcomes[fault] = cached
        elif (family, fault) in INAPPLICABLE:
            outcomes[fault] = _refuse(root, family, seed, fault, INAPPLICABLE[family, fault])
        else:
            pending.append(fault)
    reasons: list[str] = []
    for attempt in range(MAX_ATTEMPTS):
        if not pending:
            break
        judged = judge(sumo, family, seed, attempt, frames, horizon, noise)
        if isinstance(judged, str):
            reasons.append(f"{attempt}: {judged}")
            continue
        world, runs, onset = judged
        scene, sub_seed = world.built.scene, seed * 1000 + attempt
        for fault in list(pending):
            if fault not in runs:
                runs[fault] = simulate(
                    scene, FaultSpec.named(fault, onset), sub_seed, horizon, noise, FOLLOWER
                )
            run = runs[fault]
            if fault in VARIANT_FAULTS and (
                run.collision_frame < 0 or run.collided_row != scene.partner
            ):
                continue
            label = _label(world, family, fault, seed, attempt, onset, run, noise)
            outcomes[fault] = _write(root, run.log, label, family, seed, fault)
            pending.remove(fault)
    for fault in pending:
        why = "; ".join(reasons[-3:]) or "no accepted scene crashed with it"
        if fault in VARIANT_FAULTS and len(reasons) < MAX_ATTEMPTS:
            why = f"it crashed into the partner on none of the accepted scenes ({why})"
        outcomes[fault] = _refuse(
            root, family, seed, fault, f"no acceptable scene in {MAX_ATTEMPTS} attempts: {why}"
        )
    return [outcomes[f] for f in faults]


def _label(
    world: World,
    family: str,
    fault: str,
    seed: int,
    attempt: int,
    onset: int,
    run: SimResult,
    noise: Noise,
) -> dict[str, Any]:
    scene, built = world.built.scene, world.built
    label: dict[str, Any] = {
        "scenario": f"sumo:{family}",
        "family": family,
        "world": f"sumo {SUMO_VERSION}",
        "fault": fault,
        "seed": seed,
        "attempt": attempt,
        "partner_id": scene.actor_ids[scene.partner],
        "ego_id": scene.ego_id,
        "fault_onset_frame": onset if fault != "none" else -1,
        "twin_reaction_frame": world.twin.reaction_frame,
        "collision_frame": run.collision_frame,
        "total_frames": run.log.metadata.total_frames,
        "trigger_frame": scene.trigger_frame,
        "sumo": {
            "partner": built.partner,
            "frame0_step": built.first,
            "passes": world.passes,
            "timing_error_s": round(world.timing_error_s, 2),
            "actors": len(scene.actor_ids),
            "parameters": world.setup.params,
        },
    }
    if noise.level != 1.0:
        label["noise"] = noise.level
    return label


def _folder(root: Path, family: str, seed: int, fault: str) -> Path:
    return root / family / f"seed-{seed:03d}" / canonical_fault(fault).replace(":", "-")


def _write(
    root: Path, log: RunLog, label: dict[str, Any], family: str, seed: int, fault: str
) -> Outcome:
    meta = log.metadata
    log.metadata = type(meta)(
        meta.timesteps_per_frame,
        meta.camera_loc,
        meta.collision_frame,
        meta.total_frames,
        raw={"synthesis": label},
    )
    log.source = f"sumo:{family}:{fault}:{seed}"
    folder = _folder(root, family, seed, fault)
    partial = folder.with_name(folder.name + ".partial")
    for old in (folder, partial):
        shutil.rmtree(old, ignore_errors=True)
    partial.parent.mkdir(parents=True, exist_ok=True)
    write_run_log(log, str(partial))
    partial.rename(folder)
    return Outcome(family, fault, seed, folder, label=label)


def _refuse(root: Path, family: str, seed: int, fault: str, why: str) -> Outcome:
    folder = _folder(root, family, seed, fault)
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "refused.json").write_text(json.dumps({"refused": why}), encoding="utf-8")
    return Outcome(family, fault, seed, None, refused=why)


def _cached(root: Path, family: str, seed: int, fault: str) -> Outcome | None:
    folder = _folder(root, family, seed, fault)
    refused = folder / "refused.json"
    if refused.exists():
        why = json.loads(refused.read_text(encoding="utf-8"))["refused"]
        return Outcome(family, fault, seed, None, refused=str(why))
    meta = folder / "metadata.json"
    if meta.exists():
        label = json.loads(meta.read_text(encoding="utf-8"))["synthesis"]
        return Outcome(family, fault, seed, folder, label=label)
    return None
