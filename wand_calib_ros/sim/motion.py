"""A wand waved continuously through a scenario's volume, as a function of time.

The wand's centre follows sums of slow sinusoids per axis (random frequencies and
phases), softly limited to the volume; its direction turns in azimuth and elevation
about a random axis, as a hand turns it (about 100 deg/s, never flicking).
The motion is smooth (every derivative is continuous), so it can be sampled at any
instant: at the frame times of synchronised cameras, at each free-running camera's own
exposure times, or row by row for a rolling shutter.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.model.geometry import tangent_basis
from wand_calib_ros.core.model.rig import WandSpec
from wand_calib_ros.sim.scenarios import Scenario, sample_placements

FloatArray = NDArray[np.float64]

#: Sharpness of the soft limit that keeps the centre inside the volume (1 = gentle, large = a hard clip).
LIMIT_SHARPNESS = 5.0


@dataclass(frozen=True, eq=False)
class WandMotion:
    """The wand sampled at given instants.

    Attributes:
        times: (F,) seconds.
        wand_a: (F, 3) point A, reference frame, mm.
        direction: (F, 3) unit A -> C.
        facing: (F, 3) direction the LEDs shine into.
    """

    times: FloatArray
    wand_a: FloatArray
    direction: FloatArray
    facing: FloatArray

    def points(self, wand: WandSpec) -> FloatArray:
        """(F, 3, 3) A, B, C in the reference frame, mm."""
        return self.wand_a[:, None, :] + wand.offsets[None, :, None] * self.direction[:, None, :]


def soft_clip(x: FloatArray, sharpness: float = LIMIT_SHARPNESS) -> FloatArray:
    """A smooth clip of ``x`` to [-1, 1]: log(cosh(s(x + 1)) / cosh(s(x - 1))) / (2 s)."""
    s = sharpness

    def log_cosh(y: FloatArray) -> FloatArray:
        return np.abs(y) + np.log1p(np.exp(-2.0 * np.abs(y))) - np.log(2.0)

    return (log_cosh(s * (x + 1.0)) - log_cosh(s * (x - 1.0))) / (2.0 * s)


@dataclass(frozen=True, eq=False)
class WavedWand:
    """A smooth wand trajectory (see the module docstring); :meth:`at` samples it.

    Attributes:
        wand: the wand's lengths.
        middle: (3,) centre of the volume, mm.
        half: (3,) half its extent per axis, mm.
        frequencies: (3, 3) Hz, three sinusoids per axis of the centre.
        phases: (3, 3) rad.
        turn: (3,) Hz of the direction's azimuth (two harmonics) and elevation.
        turn_phases: (3,) rad, their phases.
        axis: (3,) unit vector the elevation is measured from.
    """

    wand: WandSpec
    middle: FloatArray
    half: FloatArray
    frequencies: FloatArray
    phases: FloatArray
    turn: FloatArray
    turn_phases: FloatArray
    axis: FloatArray

    def median_speed(self, duration_s: float = 60.0) -> float:
        """Median speed of the LEDs over ``duration_s``, mm/s."""
        times = np.linspace(0.0, duration_s, 6001)
        points = self.at(times).points(self.wand)
        return float(np.median(np.linalg.norm(np.diff(points, axis=0), axis=-1)) / (times[1] - times[0]))

    def at(self, times: FloatArray) -> WandMotion:
        """The wand at ``times`` (any shape flattened to (F,), seconds)."""
        t = np.asarray(times, dtype=np.float64).reshape(-1)
        wave = np.sin(2 * np.pi * self.frequencies[None] * t[:, None, None] + self.phases[None]).mean(axis=2)
        centre = self.middle + self.half * soft_clip(wave * 1.6)
        angle = 2 * np.pi * self.turn[None] * t[:, None] + self.turn_phases[None]  # (F, 3)
        azimuth = 0.8 * np.pi * np.sin(angle[:, 0]) + 0.4 * np.pi * np.sin(angle[:, 1])
        elevation = 1.1 * np.sin(angle[:, 2])
        e1, e2 = tangent_basis(self.axis[None])[0].T
        direction = (
            np.cos(elevation)[:, None] * (np.cos(azimuth)[:, None] * e1 + np.sin(azimuth)[:, None] * e2)
            + np.sin(elevation)[:, None] * self.axis
        )
        facing = np.cross(direction, [0.0, 1.0, 0.0])
        facing = np.where(np.linalg.norm(facing, axis=1, keepdims=True) > 1e-6, facing, [1.0, 0.0, 0.0])
        facing /= np.linalg.norm(facing, axis=1, keepdims=True)
        return WandMotion(t, centre - 0.5 * self.wand.L * direction, direction, facing)


def waved_wand(
    volume: FloatArray,
    wand: WandSpec,
    rng: np.random.Generator,
    *,
    tempo: float = 1.0,
    speed_mm_s: float | None = None,
) -> WavedWand:
    """A random smooth trajectory through ``volume`` ((2, 3) min and max corner of the wand centre, mm).

    Args:
        volume: where the wand's centre may go.
        wand: the wand.
        rng: the only source of randomness.
        tempo: scales every frequency (1: about 0.5 m/s in a 0.7 m volume, the wand turning at about
            100 deg/s; 2: twice as fast).
        speed_mm_s: if given, the tempo that makes the LEDs' median speed this (over a minute).
    """
    if speed_mm_s is not None:
        calm = waved_wand(volume, wand, rng, tempo=tempo)
        return replace(calm, frequencies=calm.frequencies * speed_mm_s / calm.median_speed(),
                       turn=calm.turn * speed_mm_s / calm.median_speed())  # fmt: skip
    low, high = np.asarray(volume, dtype=np.float64)
    frequencies = rng.uniform(0.05, 0.25, size=(3, 3)) * tempo
    phases = rng.uniform(0, 2 * np.pi, size=(3, 3))
    turn = rng.uniform(0.05, 0.25, size=3) * tempo
    turn_phases = rng.uniform(0, 2 * np.pi, size=3)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    return WavedWand(wand, (low + high) / 2, (high - low) / 2, frequencies, phases, turn, turn_phases, axis)


def shared_volume(scenario: Scenario, rng: np.random.Generator, *, placements: int = 2000) -> FloatArray:
    """(2, 3) the part of a scenario's volume where its cameras see the wand together: the 5th to
    95th percentile box of the centres of placements the scenario's sampler accepts."""
    wand_a, direction, _ = sample_placements(scenario, placements, rng)
    centres = wand_a + 0.5 * scenario.wand.L * direction
    return np.percentile(centres, [5.0, 95.0], axis=0)
