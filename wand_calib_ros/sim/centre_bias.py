"""Points whose centres brightness biases, on purpose: the truth a centre-bias model is tested against.

Each LED's brightness follows the renderer's light model (:mod:`~wand_calib_ros.sim.room`): its peak falls as 1/d^2
with its distance from the camera and as sin(a)^p with the angle a between the wand and the line of sight. A
:class:`DrawnBias` then moves the centres of the bright ones: a constant offset, a radial one (away from the
principal point), each from some brightness on, or growing with the brightness.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.model.brightness import saturated_of
from wand_calib_ros.core.model.rig import WandObservations
from wand_calib_ros.sim.scenarios import Scenario, SimulatedData

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class LedLight:
    """How bright the wand's LEDs are.

    Attributes:
        stops_at_1m: an LED 1 m away, seen side on, in stops over full scale (3: 8x full scale).
        falloff: the exponent p of sin(a)^p as the wand turns towards the line of sight.
    """

    stops_at_1m: float = 3.0
    falloff: float = 3.0


def led_brightness(scenario: Scenario, data: SimulatedData, light: LedLight = LedLight()) -> FloatArray:
    """(P, C, K) each point's brightness, stops over full scale (NaN where the camera does not see it)."""
    points = data.wand_a[:, None, :] + scenario.wand.offsets[None, :, None] * data.wand_direction[:, None, :]
    out = np.full(data.observations.uv.shape[:3], np.nan)
    for c, camera in enumerate(scenario.cameras):
        sight = points - camera.pose.center[None, None, :]  # (P, K, 3)
        distance = np.linalg.norm(sight, axis=-1)
        along = np.abs(np.einsum("pkj,pj->pk", sight, data.wand_direction)) / distance
        side_on = np.sqrt(np.clip(1.0 - along**2, 1e-6, 1.0))
        stops = light.stops_at_1m + 2.0 * np.log2(1000.0 / distance) + light.falloff * np.log2(side_on)
        out[:, c] = np.where(np.isfinite(data.observations.uv[:, c, :, 0]), stops, np.nan)
    return out


@dataclass(frozen=True)
class DrawnBias:
    """A centre bias drawn on purpose.

    Attributes:
        offset_px: (u, v) the constant offset of a biased centre, px.
        radial_px: its offset away from the principal point, px.
        from_stops: the brightness (stops over full scale) from which centres are biased.
        per_stop: False: the offsets are whole from ``from_stops`` on; True: they grow by themselves per stop
            beyond it.
        cameras: the cameras biased (indices; None: all).
        grows: with ``per_stop`` False, the whole offsets from ``from_stops`` on grow by this fraction of themselves
            per stop beyond it (a step and a growth: a LINEAR bias).
    """

    offset_px: tuple[float, float] = (0.0, 0.0)
    radial_px: float = 0.0
    from_stops: float = 0.0
    per_stop: bool = False
    cameras: tuple[int, ...] | None = None
    grows: float = 0.0

    def sizes(self, brightness: FloatArray) -> FloatArray:
        """How much of the offsets each point (any shape, stops over full scale) gets: 0 or 1 (plus ``grows`` per stop
        beyond ``from_stops``), or the stops beyond it."""
        beyond = np.nan_to_num(brightness - self.from_stops, nan=-1.0)
        if self.per_stop:
            return np.clip(beyond, 0.0, None)
        return (beyond >= 0) * (1.0 + self.grows * np.clip(beyond, 0.0, None))

    def class_truth(self, camera: int, stops: FloatArray) -> FloatArray:
        """(3,) the (u, v, radial) offsets of the points of one class of ``camera`` on average, their brightness
        ``stops`` (N,): what a calibration should report for that class."""
        if self.cameras is not None and camera not in self.cameras:
            return np.zeros(3)
        return np.array([*self.offset_px, self.radial_px]) * float(np.mean(self.sizes(stops)))

    def offsets(self, scenario: Scenario, uv: FloatArray, brightness: FloatArray) -> FloatArray:
        """(P, C, K, 2) how far each point's centre is moved."""
        size = self.sizes(brightness)
        out = np.zeros(uv.shape)
        for c, camera in enumerate(scenario.cameras):
            if self.cameras is not None and c not in self.cameras:
                continue
            away = uv[:, c] - camera.model.principal_point
            away = away / np.maximum(np.linalg.norm(away, axis=-1, keepdims=True), 1e-9)
            shift = np.asarray(self.offset_px)[None, None, :] + self.radial_px * away
            out[:, c] = np.nan_to_num(size[:, c, :, None] * shift)
        return out


def with_bias(
    scenario: Scenario, data: SimulatedData, bias: DrawnBias | None, light: LedLight = LedLight()
) -> SimulatedData:
    """``data`` with each point's brightness, and its centre moved by ``bias`` (None: only the brightness)."""
    observations = data.observations
    brightness = led_brightness(scenario, data, light)
    uv = observations.uv if bias is None else observations.uv + bias.offsets(scenario, observations.uv, brightness)
    moved = WandObservations(
        observations.frames, observations.camera_names, uv, observations.stamps, saturated_of(brightness), brightness
    )
    return replace(data, observations=moved)
