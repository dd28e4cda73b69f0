"""Rendering of LED wand images: Gaussian spots on a dark, noisy background.

A scenario's wand is waved continuously (smooth motion through the volume at a
given frame rate) and each camera's image shows its three LEDs as Gaussian
spots of a few pixels at their exact projections, with sensor noise and,
optionally, spurious reflections and occluded LEDs. These images are the test
and demo data of the detector, the bag tools and the ROS nodes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.camera_model import project
from wand_calib_ros.sim.scenarios import Scenario, sample_placements, visibility

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class RenderOptions:
    """How the LEDs and the sensor look.

    Attributes:
        spot_sigma_px: standard deviation of an LED spot, px.
        brightness: spot peak above the background (grey levels, 8 bit).
        background: background level.
        read_noise: Gaussian noise, grey levels.
        reflection_rate: probability per image of one extra, LED-like spot somewhere.
        occlusion_rate: probability per LED and image that it is hidden.
    """

    spot_sigma_px: float = 1.3
    brightness: float = 180.0
    background: float = 12.0
    read_noise: float = 2.0
    reflection_rate: float = 0.0
    occlusion_rate: float = 0.0


@dataclass(frozen=True, eq=False)
class WandMotion:
    """A continuous wand trajectory sampled at the frame times.

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


def wave_wand(scenario: Scenario, n_frames: int, fps: float, rng: np.random.Generator) -> WandMotion:
    """A smooth wand motion through the scenario's volume (sums of slow sinusoids, random phases)."""
    times = np.arange(n_frames) / fps
    low, high = scenario.volume
    middle, half = (low + high) / 2, (high - low) / 2
    frequencies = rng.uniform(0.05, 0.25, size=(3, 3))  # Hz, three components per axis
    phases = rng.uniform(0, 2 * np.pi, size=(3, 3))
    wave = np.sin(2 * np.pi * frequencies[None] * times[:, None, None] + phases[None]).mean(axis=2)
    centre = middle + half * np.clip(wave * 1.6, -1, 1)
    spin = rng.uniform(0.1, 0.4, size=3)
    tilt = rng.uniform(0, 2 * np.pi, size=3)
    direction = np.stack([np.sin(2 * np.pi * spin[i] * times + tilt[i]) for i in range(3)], axis=1)
    direction += 0.3 * rng.normal(size=3)
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    facing = np.cross(direction, [0.0, 1.0, 0.0])
    facing = np.where(np.linalg.norm(facing, axis=1, keepdims=True) > 1e-6, facing, [1.0, 0.0, 0.0])
    facing /= np.linalg.norm(facing, axis=1, keepdims=True)
    wand_a = centre - 0.5 * scenario.wand.L * direction
    return WandMotion(times, wand_a, direction, facing)


def true_pixels(scenario: Scenario, motion: WandMotion) -> FloatArray:
    """(F, C, 3, 2) exact projections of A, B, C (NaN where a camera cannot see the LED)."""
    points = motion.wand_a[:, None, :] + scenario.wand.offsets[None, :, None] * motion.direction[:, None, :]
    seen = visibility(scenario, motion.wand_a, motion.direction, motion.facing)
    uv = np.full((points.shape[0], len(scenario.cameras), 3, 2), np.nan)
    for c, camera in enumerate(scenario.cameras):
        uv[:, c] = np.where(seen[:, c, :, None], project(camera.model, camera.pose.apply(points)), np.nan)
    return uv


def render_image(
    image_size: tuple[int, int], spots: FloatArray, options: RenderOptions, rng: np.random.Generator
) -> NDArray[np.uint8]:
    """A mono8 image with Gaussian spots at (N, 2) sub-pixel positions (NaN rows are skipped)."""
    width, height = image_size
    image = np.full((height, width), options.background, dtype=np.float64)
    radius = int(np.ceil(4 * options.spot_sigma_px))
    offsets = np.arange(-radius, radius + 1)
    for u, v in spots[np.all(np.isfinite(spots), axis=1)]:
        cu, cv = round(float(u)), round(float(v))
        xs, ys = cu + offsets, cv + offsets
        gx = np.exp(-0.5 * ((xs - u) / options.spot_sigma_px) ** 2)
        gy = np.exp(-0.5 * ((ys - v) / options.spot_sigma_px) ** 2)
        keep_x, keep_y = (xs >= 0) & (xs < width), (ys >= 0) & (ys < height)
        image[np.ix_(ys[keep_y], xs[keep_x])] += options.brightness * np.outer(gy[keep_y], gx[keep_x])
    image += rng.normal(scale=options.read_noise, size=image.shape)
    return np.clip(np.round(image), 0, 255).astype(np.uint8)


def render_frame(
    image_size: tuple[int, int], uv: FloatArray, options: RenderOptions, rng: np.random.Generator
) -> tuple[NDArray[np.uint8], FloatArray]:
    """One camera's image of the wand, with the occlusions and reflections of ``options``.

    Args:
        image_size: (width, height).
        uv: (3, 2) exact pixels of A, B, C (NaN where not visible).

    Returns:
        The image and the (3, 2) pixels actually drawn (NaN where occluded or not visible).
    """
    drawn = uv.copy()
    hidden = rng.random(3) < options.occlusion_rate
    drawn[hidden] = np.nan
    spots = drawn
    if rng.random() < options.reflection_rate:
        width, height = image_size
        spots = np.vstack([drawn, rng.uniform([0, 0], [width - 1, height - 1])])
    return render_image(image_size, spots, options, rng), drawn


@dataclass(frozen=True, eq=False)
class Recording:
    """Rendered images of a waved wand with the pixels drawn.

    Attributes:
        frames: (camera, stamp_ns, mono8 image) in time order.
        drawn: (F, C, 3, 2) pixels of A, B, C actually drawn (NaN: hidden or out of view).
        stamps_ns: (F,) frame times.
    """

    frames: list[tuple[str, int, NDArray[np.uint8]]]
    drawn: FloatArray
    stamps_ns: NDArray[np.int64]


def independent_placements(scenario: Scenario, n_frames: int, fps: float, rng: np.random.Generator) -> WandMotion:
    """Unrelated wand placements (the scenario's sampler), one per second whatever ``fps``: a wand put
    down and picked up again, with no continuity to track."""
    wand_a, direction, facing = sample_placements(scenario, n_frames, rng)
    return WandMotion(np.arange(n_frames, dtype=np.float64), wand_a, direction, facing)


def render_recording(
    scenario: Scenario,
    n_frames: int,
    fps: float,
    options: RenderOptions,
    rng: np.random.Generator,
    *,
    independent: bool = False,
) -> Recording:
    """Images of every camera (hardware-synchronised) of a wand waved through the scenario's volume,
    or of independent placements when ``independent``."""
    motion = (independent_placements if independent else wave_wand)(scenario, n_frames, fps, rng)
    uv = true_pixels(scenario, motion)
    stamps = np.round(motion.times * 1e9).astype(np.int64) + 1_700_000_000 * 10**9
    frames = []
    drawn = np.full_like(uv, np.nan)
    for f in range(n_frames):
        for c, camera in enumerate(scenario.cameras):
            image, drawn[f, c] = render_frame(camera.spec.image_size, uv[f, c], options, rng)
            frames.append((camera.spec.name, int(stamps[f]), image))
    return Recording(frames, drawn, stamps)
