"""Rendering of LED wand images: Gaussian spots on a dark, noisy background.

A scenario's wand is waved continuously (smooth motion through the volume) and
each camera's images, at its own clock's instants (:mod:`wand_calib_ros.sim.clocks`:
hardware-triggered or free-running, global or rolling shutter), show its three LEDs
as Gaussian spots of a few pixels at their exact projections, with sensor noise and,
optionally, spurious reflections and occluded LEDs. These images are the test and
demo data of the detector, the bag tools and the ROS nodes.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.model.camera_model import project
from wand_calib_ros.core.model.rig import WandObservations
from wand_calib_ros.sim.clocks import CameraTake, film, observe, stamp_ns, synchronised_clocks
from wand_calib_ros.sim.motion import WandMotion, waved_wand
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
        centre_scatter_px: standard deviation (px) of each spot's centre about the LED's true
            projection: real centroids scatter by a few tenths of a pixel (spot shape, diffusers,
            sensor non-uniformity) where these ideal spots are found to 0.01 px.
    """

    spot_sigma_px: float = 1.3
    brightness: float = 180.0
    background: float = 12.0
    read_noise: float = 2.0
    reflection_rate: float = 0.0
    occlusion_rate: float = 0.0
    centre_scatter_px: float = 0.0


def true_pixels(scenario: Scenario, motion: WandMotion) -> FloatArray:
    """(F, C, 3, 2) exact projections of A, B, C (NaN where a camera cannot see the LED)."""
    points = motion.points(scenario.wand)
    seen = visibility(scenario, motion.wand_a, motion.direction, motion.facing)
    uv = np.full((points.shape[0], len(scenario.cameras), scenario.wand.n_points, 2), np.nan)
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
        The image and the (3, 2) true pixels of the LEDs drawn (NaN where occluded or not visible).
    """
    drawn = uv.copy()
    hidden = rng.random(uv.shape[0]) < options.occlusion_rate
    drawn[hidden] = np.nan
    spots = (
        drawn + rng.normal(scale=options.centre_scatter_px, size=drawn.shape) if options.centre_scatter_px else drawn
    )
    if rng.random() < options.reflection_rate:
        width, height = image_size
        spots = np.vstack([drawn, rng.uniform([0, 0], [width - 1, height - 1])])
    return render_image(image_size, spots, options, rng), drawn


@dataclass(frozen=True, eq=False)
class Recording:
    """Rendered images of a waved wand with the pixels drawn.

    Attributes:
        frames: (camera, stamp_ns, mono8 image) in stamp order (cameras in rig order on a tie).
        drawn: the pixels of A, B, C actually drawn (NaN: hidden or out of view), grouped into
            frames by nearest stamps, each view with its image's stamp.
    """

    frames: list[tuple[str, int, NDArray[np.uint8]]]
    drawn: WandObservations


def independent_placements(scenario: Scenario, n_frames: int, fps: float, rng: np.random.Generator) -> WandMotion:
    """Unrelated wand placements (the scenario's sampler), one per second whatever ``fps``: a wand put
    down and picked up again, with no continuity to track."""
    wand_a, direction, facing = sample_placements(scenario, n_frames, rng)
    return WandMotion(np.arange(n_frames, dtype=np.float64), wand_a, direction, facing)


def render_take(
    scenario: Scenario, takes: tuple[CameraTake, ...], options: RenderOptions, rng: np.random.Generator
) -> Recording:
    """Every camera's images of what it filmed (each image at its own stamp)."""
    names = scenario.rig.camera_names
    frames: list[tuple[int, int, str, NDArray[np.uint8]]] = []
    drawn_takes = []
    for c, (camera, take) in enumerate(zip(scenario.cameras, takes, strict=True)):
        drawn = np.full_like(take.uv, np.nan)
        for k, stamp in enumerate(stamp_ns(take.stamps)):
            image, drawn[k] = render_frame(camera.spec.image_size, take.uv[k], options, rng)
            frames.append((int(stamp), c, camera.spec.name, image))
        drawn_takes.append(replace(take, uv=drawn))
    frames.sort(key=lambda f: (f[0], f[1]))
    observations = observe(names, tuple(drawn_takes), 0.0, rng)
    return Recording([(name, stamp, image) for stamp, _, name, image in frames], observations)


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
    if independent:
        motion = independent_placements(scenario, n_frames, fps, rng)
        uv = true_pixels(scenario, motion)
        times = np.repeat(motion.times[:, None], 3, axis=1)
        takes = tuple(CameraTake(motion.times, motion.times, uv[:, c], times) for c in range(len(scenario.cameras)))
    else:
        trajectory = waved_wand(scenario.volume, scenario.wand, rng)
        clocks = synchronised_clocks(len(scenario.cameras), fps=fps)
        takes = film(scenario, trajectory, clocks, (n_frames - 0.5) / fps, rng)
    return render_take(scenario, takes, options, rng)
