"""The synthesiser's noise level K: every sigma of the simulated stack in physical units.

Real stacks are noisier than the synthesiser's default: localisation drifts by decimetres and
camera-based 3-D positions are off by a metre at 20 m. :class:`Noise` scales each
noise source by one level K (``ads-rca synth --noise K``; 1 = the default), so nothing else
multiplies by K by hand. The random draws are the same at every level, only scaled, so K = 1
gives exactly the default output.

Localisation error is the one source the default lacks (none at K <= 1): the stack localises at
true + e_t, a pure translation drifting as an AR(1) process per axis. A common translation
changes no relative geometry, so the planner and controller behave exactly as they would at the
same perception noise without it: the loop runs on the true pose, and e_t is added to what the
stack records in its own world frame (pose, plan, 3-D detections and tracks; ground-truth
predictions are expressed relative to the localised pose), never to ground truth.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ads_rca.paramspec import Range
from ads_rca.synth.geometry import FloatArray

#: The accepted noise levels (``--noise``): from noise-free to twenty times the default.
LEVELS = Range(0.0, 20.0)
BOX_NOISE = 0.02  # σ of 2-D box corner noise, as a fraction of the box size
YAW_NOISE = float(np.radians(1.0))  # σ of the detected heading, radians
POSITION_NOISE = 0.05  # m: σ of the perceived position, plus RANGE_NOISE per metre of range
RANGE_NOISE = 0.002
EXTENT_NOISE = 0.03  # σ of the detected 3-D half extents, as a fraction
LOCALISATION_NOISE = 0.03  # m per axis per level above 1
LOCALISATION_CORRELATION = 0.98  # per frame: the error drifts over seconds
#: Second element of the localisation generator's seed: a stream of its own, so adding
#: localisation error changes no other random number.
LOCALISATION_STREAM = 13


@dataclass(frozen=True)
class Noise:
    """Noise level ``level`` (K); ``localisation=False`` leaves the pose exact at any K."""

    level: float = 1.0
    localisation: bool = True

    @property
    def box(self) -> float:
        """σ of each 2-D box corner, as a fraction of the box size."""
        return BOX_NOISE * self.level

    @property
    def yaw(self) -> float:
        """σ of the detected heading (radians)."""
        return YAW_NOISE * self.level

    def position(self, distance: FloatArray) -> FloatArray:
        """σ (m) of the perceived position at ``distance`` (m) from the ego."""
        sigma: FloatArray = (POSITION_NOISE + RANGE_NOISE * distance) * self.level
        return sigma

    @property
    def extent(self) -> float:
        """σ of the detected 3-D half extents, as a fraction."""
        return EXTENT_NOISE * self.level

    @property
    def localisation_sigma(self) -> float:
        """Stationary σ (m per axis) of the localisation error: none up to K = 1."""
        if not self.localisation:
            return 0.0
        return LOCALISATION_NOISE * max(self.level - 1.0, 0.0)

    def localisation_error(self, seed: int, frames: int) -> FloatArray | None:
        """The localisation error e_t (frames, 2) of a run, or None when there is none.

        Drawn from its own generator (``[seed, LOCALISATION_STREAM]``), the same draws
        whatever the fault, so a faulty run keeps its twin's error."""
        sigma = self.localisation_sigma
        if sigma == 0.0:
            return None
        white = np.random.default_rng([seed, LOCALISATION_STREAM]).standard_normal((frames, 2))
        rho = LOCALISATION_CORRELATION
        error = np.empty((frames, 2))
        error[0] = sigma * white[0]
        step = sigma * np.sqrt(1.0 - rho * rho)
        for t in range(1, frames):
            error[t] = rho * error[t - 1] + step * white[t]
        return error


DEFAULT_NOISE = Noise()
