"""Closed-loop scenario synthesiser with fault injection (pure Python + numpy, no ROS).

``synthesise(scenario, fault, seed)`` returns a :class:`~ads_rca.model.RunLog` in the seed
format: the scene is drawn from the seed, run fault-free (the twin) to find where the
planner had to react to the partner, and run again with the fault from just before that
frame. A seed's scene is accepted only if the twin does not crash and every fault does
(hitting the partner); otherwise the next attempt derived from the seed is tried, so the
same seed always gives the same scene whatever the fault, and ``fault="none"`` is the twin.
A variant fault (:data:`VARIANT_FAULTS`, e.g. ``perception:shifted``) takes the seed's scene
too when it crashes into the partner there, else the next scene that is accepted and where it
does (the summary's ``attempt`` says which); it never changes the other faults' scenes.
``noise=K`` scales the stack's noise (:mod:`ads_rca.synth.noise`); a scene is accepted at
each level on its own, since perception noise changes the closed loop.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NotRequired, TypedDict

from ads_rca.errors import ConfigError
from ads_rca.model import RunLog
from ads_rca.synth.errors import SynthesisError
from ads_rca.synth.faults import (
    ALL_FAULTS,
    FAULTS,
    NO_FAULT,
    VARIANT_FAULTS,
    FaultSpec,
    canonical_fault,
    fault_module,
    onset_for,
)
from ads_rca.synth.noise import LEVELS, Noise
from ads_rca.synth.scenarios import BUILDERS, DEFAULT_FRAMES, SCENARIOS
from ads_rca.synth.simulate import SimResult, simulate
from ads_rca.synth.world import Scene

if TYPE_CHECKING:
    import numpy as np

__all__ = [
    "ALL_FAULTS",
    "FAULTS",
    "SCENARIOS",
    "VARIANT_FAULTS",
    "Noise",
    "SynthesisError",
    "SynthesisSummary",
    "canonical_fault",
    "fault_module",
    "synthesise",
    "synthesise_run",
]

MAX_ATTEMPTS = 25
DEFAULT_HORIZON = 30
#: (scenario, seed, attempt, frames, actors, horizon, noise) -> whether every fault hits the
#: partner.
_Key = tuple[str, int, int, int, int, int, Noise]
_ACCEPTED: dict[_Key, bool] = {}
#: Variants that cannot turn a scenario's near miss into a crash, and why.
INAPPLICABLE = {
    ("pedestrian_crossing", "perception:shrunk"): (
        "a pedestrian's 0.5 m box shrunk recedes 0.35 m, less than the planner's 1 m margin"
    ),
    ("left_turn", "perception:shifted"): (
        "the oncoming car crosses the turning path; moved sideways it still does"
    ),
}
#: The same key and a variant fault -> whether that variant hits the partner too.
_VARIANT_HITS: dict[tuple[_Key, str], bool] = {}


class SynthesisSummary(TypedDict):
    """What :func:`synthesise_run` made: metadata ``raw["synthesis"]`` holds the same."""

    scenario: str
    fault: str
    seed: int
    attempt: int
    partner_id: str | None
    ego_id: str
    fault_onset_frame: int  # -1 without a fault
    twin_reaction_frame: int
    collision_frame: int
    total_frames: int
    noise: NotRequired[float]  # the noise level, only when it is not the default 1


def synthesise(
    scenario: str, fault: str, seed: int, noise: float | Noise = 1.0, **options: int
) -> RunLog:
    """The run log of ``scenario`` with ``fault`` for ``seed`` at noise level ``noise``.

    Options: ``frames`` (log length without a crash), ``actors`` (background actors),
    ``horizon`` (prediction keys and plan steps). Metadata ``raw["synthesis"]`` records the
    scenario, fault, seed, attempt, partner id, onset and the twin's reaction frame, and the
    noise level when it is not 1 (a :class:`~ads_rca.synth.noise.Noise` may also turn the
    localisation error off).
    """
    return synthesise_run(scenario, fault, seed, noise, **options)[0]


def synthesise_run(
    scenario: str, fault: str, seed: int, noise: float | Noise = 1.0, **options: int
) -> tuple[RunLog, SynthesisSummary]:
    """:func:`synthesise`, also returning the synthesis summary."""
    level = noise if isinstance(noise, Noise) else Noise(float(noise))
    try:
        LEVELS.check("noise", level.level)
    except ConfigError as error:
        raise SynthesisError(str(error)) from None
    fault = canonical_fault(fault)
    if scenario not in BUILDERS:
        raise SynthesisError(f"unknown scenario {scenario!r}; choose from {', '.join(SCENARIOS)}")
    if fault not in ALL_FAULTS:
        raise SynthesisError(f"unknown fault {fault!r}; choose from {', '.join(ALL_FAULTS)}")
    unknown = set(options) - {"frames", "actors", "horizon"}
    if unknown:
        raise SynthesisError(f"unknown options {sorted(unknown)}")
    horizon = int(options.get("horizon", DEFAULT_HORIZON))
    if scenario == "cruise":
        if fault != "none":
            raise SynthesisError("the cruise scenario has no partner; only fault 'none' applies")
        frames = int(options.get("frames", 2000))
        scene = BUILDERS[scenario](_rng(seed, 0), frames, int(options.get("actors", 50)))
        run = simulate(scene, NO_FAULT, seed, horizon, level)
        return _finish(run, scene, scenario, fault, seed, 0, -1, -1, level)

    if (scenario, fault) in INAPPLICABLE:
        raise SynthesisError(
            f"{fault} cannot crash the {scenario} scenario: {INAPPLICABLE[scenario, fault]}"
        )
    frames = int(options.get("frames", DEFAULT_FRAMES[scenario]))
    actors = int(options.get("actors", -1))
    for attempt in range(MAX_ATTEMPTS):
        rng = _rng(seed, attempt)
        n_background = actors if actors >= 0 else int(rng.integers(2, 7))
        scene = BUILDERS[scenario](rng, frames, n_background)
        sub_seed = seed * 1000 + attempt
        twin = simulate(scene, NO_FAULT, sub_seed, horizon, level)
        if twin.collision_frame >= 0 or twin.reaction_frame < 0:
            continue
        onset = onset_for(twin.reaction_frame)
        key = (scenario, seed, attempt, frames, actors, horizon, level)
        runs: dict[str, SimResult] = {"none": twin}
        if key not in _ACCEPTED:
            ok = True
            for module in FAULTS[1:]:
                runs[module] = simulate(scene, FaultSpec(module, onset), sub_seed, horizon, level)
                run = runs[module]
                if run.collision_frame < 0 or run.collided_row != scene.partner:
                    ok = False
                    break
            _ACCEPTED[key] = ok
        if not _ACCEPTED[key]:
            continue
        if _VARIANT_HITS.get((key, fault)) is False:
            continue
        if fault not in runs:
            runs[fault] = simulate(scene, FaultSpec.named(fault, onset), sub_seed, horizon, level)
        if fault in VARIANT_FAULTS:
            run = runs[fault]
            hit = run.collision_frame >= 0 and run.collided_row == scene.partner
            _VARIANT_HITS[key, fault] = hit
            if not hit:
                continue
        return _finish(
            runs[fault], scene, scenario, fault, seed, attempt, onset, twin.reaction_frame, level
        )
    raise SynthesisError(
        f"no acceptable {scenario} scene for seed {seed} in {MAX_ATTEMPTS} attempts"
    )


def _rng(seed: int, attempt: int) -> np.random.Generator:
    import numpy as np

    return np.random.default_rng([seed, attempt, 0x5EED])


def _finish(
    run: SimResult,
    scene: Scene,
    scenario: str,
    fault: str,
    seed: int,
    attempt: int,
    onset: int,
    reaction: int,
    noise: Noise,
) -> tuple[RunLog, SynthesisSummary]:
    partner = scene.actor_ids[scene.partner] if scene.partner >= 0 else None
    summary: SynthesisSummary = {
        "scenario": scenario,
        "fault": fault,
        "seed": seed,
        "attempt": attempt,
        "partner_id": partner,
        "ego_id": scene.ego_id,
        "fault_onset_frame": onset if fault != "none" else -1,
        "twin_reaction_frame": reaction,
        "collision_frame": run.collision_frame,
        "total_frames": run.log.metadata.total_frames,
    }
    if noise.level != 1.0:
        summary["noise"] = noise.level
    meta = run.log.metadata
    run.log.metadata = type(meta)(
        meta.timesteps_per_frame,
        meta.camera_loc,
        meta.collision_frame,
        meta.total_frames,
        raw={"synthesis": summary},
    )
    run.log.source = f"synth:{scenario}:{fault}:{seed}"
    return run.log, summary
