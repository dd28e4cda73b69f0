"""Camera clocks of simulated rigs: hardware-triggered or free-running, global or rolling shutter.

A camera exposes at ``phase + k / fps``; its driver stamps each image ``latency``
later, with Gaussian ``jitter``. A rolling shutter reads row v of an H-row image
``readout * v / H`` after the first, so each LED is seen at its own instant. The
calibration's contract is **exposure = stamp - time_offset** (+ readout x v / H for a
rolling shutter): a camera's true ``time_offset`` is its latency.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.collection.sync import frames_to_observations, group_by_stamps
from wand_calib_ros.core.model.camera_model import project
from wand_calib_ros.core.model.rig import WandObservations
from wand_calib_ros.sim.motion import WavedWand, shared_volume, waved_wand
from wand_calib_ros.sim.scenarios import Scenario, visibility

FloatArray = NDArray[np.float64]

#: Fixed-point iterations that find when a rolling shutter sees each LED (converges geometrically).
ROLLING_ITERATIONS = 4


@dataclass(frozen=True)
class CameraClock:
    """When one simulated camera exposes and how its images are stamped.

    Attributes:
        fps: frame rate, Hz.
        phase_s: first exposure, s.
        latency_s: stamp minus exposure (the driver's constant delay), s.
        jitter_s: standard deviation of Gaussian noise on each stamp, s.
        readout_s: rolling-shutter readout time of the whole image (0: global shutter), s.
    """

    fps: float = 30.0
    phase_s: float = 0.0
    latency_s: float = 0.0
    jitter_s: float = 0.0
    readout_s: float = 0.0

    def exposures(self, duration_s: float) -> FloatArray:
        """(N,) exposure instants (of the image's first row) in [0, duration_s), s."""
        first = int(np.ceil(-self.phase_s * self.fps - 1e-9))
        k = np.arange(first, int(np.floor((duration_s - self.phase_s) * self.fps - 1e-9)) + 1)
        return self.phase_s + k / self.fps


def synchronised_clocks(n_cameras: int, *, fps: float = 30.0) -> tuple[CameraClock, ...]:
    """Hardware-triggered global-shutter cameras: one exposure instant for all, stamped exactly."""
    return tuple(CameraClock(fps) for _ in range(n_cameras))


def free_running_clocks(
    n_cameras: int,
    rng: np.random.Generator,
    *,
    fps: float | tuple[float, ...] = 30.0,
    max_phase_frames: float = 0.5,
    max_latency_s: float = 0.008,
    jitter_s: float = 0.0002,
    readout_s: float = 0.0,
) -> tuple[CameraClock, ...]:
    """Cameras that each expose at their own phase (uniform in +-max_phase_frames of a frame) and whose
    drivers stamp with a constant latency (uniform in +-max_latency_s) and jitter.

    Args:
        fps: one rate for all cameras or one per camera.
    """
    rates = np.broadcast_to(np.asarray(fps, dtype=np.float64), (n_cameras,))
    phases = rng.uniform(-max_phase_frames, max_phase_frames, n_cameras) / rates
    latencies = rng.uniform(-max_latency_s, max_latency_s, n_cameras)
    return tuple(
        CameraClock(float(r), float(p), float(lat), jitter_s, readout_s)
        for r, p, lat in zip(rates, phases, latencies, strict=True)
    )


@dataclass(frozen=True, eq=False)
class CameraTake:
    """What one camera filmed.

    Attributes:
        exposures: (N,) exposure instants of its images (first row), s.
        stamps: (N,) the images' stamps, s.
        uv: (N, K, 2) exact pixels of the markers (NaN where it cannot see the LED).
        point_times: (N, K) the instant each LED was seen (exposure + readout x v / H), s.
    """

    exposures: FloatArray
    stamps: FloatArray
    uv: FloatArray
    point_times: FloatArray


def film(
    scenario: Scenario,
    trajectory: WavedWand,
    clocks: tuple[CameraClock, ...],
    duration_s: float,
    rng: np.random.Generator,
) -> tuple[CameraTake, ...]:
    """Exact pixels of every camera's images of a waved wand, each camera on its own clock.

    Args:
        scenario: the rig (its cameras, the LEDs' emission cone).
        trajectory: the wand's motion.
        clocks: one per camera.
        duration_s: length of the take, s.
        rng: draws the stamps' jitter.
    """
    takes = []
    for c, (camera, clock) in enumerate(zip(scenario.cameras, clocks, strict=True)):
        exposures = clock.exposures(duration_s)
        times = np.repeat(exposures[:, None], scenario.wand.n_points, axis=1)
        height = camera.spec.image_size[1]
        for _ in range(ROLLING_ITERATIONS if clock.readout_s else 1):
            uv, seen = _seen_at(scenario, trajectory, c, times)
            if clock.readout_s:
                rows = np.where(np.isfinite(uv[..., 1]), uv[..., 1], 0.0)
                times = exposures[:, None] + clock.readout_s * rows / height
        uv, seen = _seen_at(scenario, trajectory, c, times)
        stamps = exposures + clock.latency_s + rng.normal(scale=clock.jitter_s, size=exposures.shape)
        takes.append(CameraTake(exposures, stamps, np.where(seen[..., None], uv, np.nan), times))
    return tuple(takes)


def _seen_at(
    scenario: Scenario, trajectory: WavedWand, camera: int, times: FloatArray
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """(N, K, 2) pixels and (N, K) visibility of each LED in one camera, LED p at ``times[:, p]``."""
    uv = np.empty((*times.shape, 2))
    seen = np.empty(times.shape, dtype=bool)
    model, pose = scenario.cameras[camera].model, scenario.cameras[camera].pose
    for p in range(times.shape[1]):
        motion = trajectory.at(times[:, p])
        points = motion.points(scenario.wand)[:, p]
        uv[:, p] = project(model, pose.apply(points))
        seen[:, p] = visibility(scenario, motion.wand_a, motion.direction, motion.facing)[:, camera, p]
    return uv, seen


#: Stamps of simulated takes start here (seconds since the epoch, as a driver's header stamps would).
EPOCH_S = 1_700_000_000


def stamp_ns(seconds: FloatArray) -> NDArray[np.int64]:
    """Simulated times (s from the start of a take) as header stamps in ns."""
    return (np.round(np.asarray(seconds) * 1e9) + EPOCH_S * 10**9).astype(np.int64)


def observe(
    names: tuple[str, ...], takes: tuple[CameraTake, ...], noise_px: float, rng: np.random.Generator
) -> WandObservations:
    """The observations a collector would store: each camera's images with Gaussian pixel noise,
    grouped into frames by nearest stamps, every view with its own stamp. Frame ids count every
    frame (frames in which no camera saw the wand are left out, so ids are consecutive only
    where the wand was seen)."""
    detections = []
    for name, take in zip(names, takes, strict=True):
        noisy = take.uv + rng.normal(scale=noise_px, size=take.uv.shape) if noise_px > 0 else take.uv
        for stamp, points in zip(stamp_ns(take.stamps), noisy, strict=True):
            detections.append((name, int(stamp), points if np.isfinite(points).any() else None))
    n_points = takes[0].uv.shape[1]
    return frames_to_observations(group_by_stamps(names, detections, n_points=n_points), names, n_points)


@dataclass(frozen=True)
class TakeOptions:
    """A continuous take: how long, how fast the wand moves, and the cameras' clocks.

    Attributes:
        duration_s: length of the take, s.
        fps: one frame rate for every camera, or one per camera, Hz.
        free_running: cameras expose at their own phase and stamp with their own latency (else
            hardware-triggered: one instant, exact stamps).
        max_phase_frames: free-running phases are uniform in +- this fraction of a frame.
        max_latency_s: free-running latencies are uniform in +- this, s.
        jitter_s: standard deviation of the stamps' noise (free-running), s.
        readout_s: rolling-shutter readout time of every camera (0: global shutter), s.
        speed_mm_s: median speed of the LEDs, mm/s.
    """

    duration_s: float = 20.0
    fps: float | tuple[float, ...] = 30.0
    free_running: bool = True
    max_phase_frames: float = 0.5
    max_latency_s: float = 0.008
    jitter_s: float = 0.0002
    readout_s: float = 0.0
    speed_mm_s: float = 1000.0

    def clocks(self, n_cameras: int, rng: np.random.Generator) -> tuple[CameraClock, ...]:
        """The cameras' clocks of this take (random phases and latencies when free-running)."""
        if self.free_running:
            return free_running_clocks(
                n_cameras,
                rng,
                fps=self.fps,
                max_phase_frames=self.max_phase_frames,
                max_latency_s=self.max_latency_s,
                jitter_s=self.jitter_s,
                readout_s=self.readout_s,
            )
        rates = np.broadcast_to(np.asarray(self.fps, dtype=np.float64), (n_cameras,))
        return tuple(CameraClock(float(r), readout_s=self.readout_s) for r in rates)


def take_trajectory(scenario: Scenario, options: TakeOptions, rng: np.random.Generator) -> WavedWand:
    """A wand waved at the take's speed through the part of the volume the cameras see together."""
    return waved_wand(shared_volume(scenario, rng), scenario.wand, rng, speed_mm_s=options.speed_mm_s)


def truth_timing(names: tuple[str, ...], clocks: tuple[CameraClock, ...]) -> dict[str, dict[str, float]]:
    """Per camera the true timing in the result's keys (time_offset_s = latency: exposure = stamp - offset)."""
    return {
        name: {
            "time_offset_s": clock.latency_s,
            "rolling_shutter_readout_s": clock.readout_s,
            "fps": clock.fps,
            "phase_s": clock.phase_s,
        }
        for name, clock in zip(names, clocks, strict=True)
    }
