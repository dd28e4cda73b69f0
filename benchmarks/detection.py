"""Detection throughput per core: a camera's stream of images through the whole detector (background, masks,
blobs, centres, wand, track, labels), on clean spots and on a room's images (two lamps, a window, LEDs fading
with distance, streaks over a 6 ms exposure, shot and read noise).

Run: .venv/bin/python benchmarks/detection.py
Targets on this machine: >= 1000 images/s at 640x480 mono8, >= 250 images/s at 1280x1024 (one core, CPU time).
"""

from __future__ import annotations

import time

import cv2
import numpy as np

from wand_calib_ros.core.model.rig import CameraSpec
from wand_calib_ros.detection.recording import CameraStream
from wand_calib_ros.detection.wand import WandOptions
from wand_calib_ros.sim.render import RenderOptions, render_image
from wand_calib_ros.sim.room import CameraRoom, Lamp, Window
from wand_calib_ros.sim.room_images import render_camera

IMAGES = 150
REPEATS = 4
#: Each case's first this many images go through a stream of their own first, untimed: a process's first use of
#: each code path (its caches, its first calls) is not the cost of a camera's stream.
WARM_UP = 30
#: The camera: a 1.8 mm fisheye on a sensor 3.6 mm across, at either resolution (5.6 um pixels at 640x480, 2.8 um
#: at 1280x1024). The wand's LEDs are drawn on a straight line in the image: near the image centre that is a
#: straight wand's, within the collinearity check's tolerance, at both resolutions. (With 5.6 um pixels at
#: 1280x1024 the image's sides would be 114 deg off the axis, beyond the lens's 92.5, and 38 % of the views no
#: straight wand's: rejected as not collinear, not a stream a camera sends.)
SENSOR_WIDTH_MM = 3.584


def camera(size: tuple[int, int]) -> CameraSpec:
    """The benchmark's camera at ``size`` (width, height) pixels."""
    pixel_um = 1000.0 * SENSOR_WIDTH_MM / size[0]
    return CameraSpec("cam", size, (pixel_um, pixel_um), 1.8, 92.5)


def _wand_paths(size: tuple[int, int], rng: np.random.Generator) -> list[np.ndarray]:
    """(3, 2) A, B, C per image of a wand sweeping across the image (120 px long, turning)."""
    width, height = size
    centre = np.array([width / 2, height / 2])
    out = []
    for k in range(IMAGES):
        angle = 0.05 * k
        direction = np.array([np.cos(angle), np.sin(angle)])
        middle = centre + 0.3 * np.array([width * np.sin(0.03 * k), height * np.cos(0.021 * k)])
        out.append(middle + np.outer([-90.0, 30.0, 90.0], direction) + rng.normal(scale=0.2, size=(3, 2)))
    return out


def clean_images(size: tuple[int, int], rng: np.random.Generator) -> list[np.ndarray]:
    """Gaussian spots on a dark field (sim.render)."""
    return [render_image(size, spots, RenderOptions(), rng) for spots in _wand_paths(size, rng)]


def room_images(size: tuple[int, int], rng: np.random.Generator) -> list[np.ndarray]:
    """A room's images: two lamps, a window, LEDs streaking over the exposure (sim.room)."""
    width, height = size
    room = CameraRoom(
        lamps=(Lamp((0.15 * width, 0.7 * height), 3.0, 900.0), Lamp((0.8 * width, 0.25 * height), 4.0, 1500.0)),
        windows=(Window((0.55 * width, 0.05 * height, 0.85 * width, 0.3 * height), 30.0),),
    )
    points = _wand_paths(size, rng)
    paths, energy = [], []
    for k, now in enumerate(points):
        after = points[min(k + 1, len(points) - 1)]
        steps = np.linspace(0.0, 0.2, 9)  # the LEDs move a fifth of a frame's motion over the exposure
        path = now[:, None, :] + steps[None, :, None] * (after - now)[:, None, :]
        paths.append(path)
        energy.append(np.full(path.shape[:2], 6.0 * 2 * np.pi * rng.uniform(20.0, 300.0) / 9))
    images, _, _, _ = render_camera(room, size, paths, energy, rng)
    return [np.asarray(image) for image in images]


def rate(spec: CameraSpec, images: list[np.ndarray]) -> float:
    """Images per second of CPU time through a CameraStream (detect and label, as the nodes and detect run), after a
    warm-up (WARM_UP); the stream's own start (its static structure learned) is timed."""
    warm = CameraStream(spec, WandOptions())
    for k, image in enumerate(images[:WARM_UP]):
        warm.push((k + 1) * 33_333_333, image, "mono8")
    stream = CameraStream(spec, WandOptions())
    stamp = 0
    begin = time.process_time()
    for _ in range(REPEATS):
        for image in images:
            stamp += 33_333_333
            stream.push(stamp, image, "mono8")
    return REPEATS * len(images) / (time.process_time() - begin)


def main() -> None:
    cv2.setNumThreads(1)  # one core: OpenCV's thread pool only adds overhead on these small operations
    rng = np.random.default_rng(0)
    for size, target in (((640, 480), 1000), ((1280, 1024), 250)):
        spec = camera(size)
        for name, make in (("clean spots", clean_images), ("room", room_images)):
            images = make(size, rng)
            print(
                f"{size[0]}x{size[1]} mono8, {name}: {rate(spec, images):.0f} images/s per core "
                f"(CPU time; target >= {target})"
            )


if __name__ == "__main__":
    main()
