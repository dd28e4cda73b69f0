"""Detection throughput per core: rendered LED wand images through blob extraction and wand identification.

Run: .venv/bin/python benchmarks/detection.py
Targets on this machine: >= 1000 frames/s at 640x480 mono8, >= 250 frames/s at 1280x1024 (one core).
"""

from __future__ import annotations

import time

import cv2
import numpy as np

from wand_calib_ros.core.initialise.intrinsics_init import nominal_bearings
from wand_calib_ros.core.model.rig import CameraSpec
from wand_calib_ros.detection.blobs import BlobOptions
from wand_calib_ros.detection.recording import detect_image
from wand_calib_ros.detection.wand import WandOptions
from wand_calib_ros.sim.render import RenderOptions, render_image


def main() -> None:
    cv2.setNumThreads(1)  # one core: OpenCV's thread pool only adds overhead on these small operations
    rng = np.random.default_rng(0)
    for size, target in (((640, 480), 1000), ((1280, 1024), 250)):
        spec = CameraSpec("cam", size, (5.6, 5.6), 1.8, 92.5)
        model = nominal_bearings(spec)
        images = []
        for _ in range(50):
            start = rng.uniform([50, 50], [size[0] - 250, size[1] - 150])
            direction = rng.normal(size=2)
            direction /= np.linalg.norm(direction)
            spots = start + np.outer([0.0, 120.0, 180.0], direction)
            images.append(render_image(size, spots, RenderOptions(), rng))
        repeats = 10
        begin = time.process_time()
        for _ in range(repeats):
            for image in images:
                detect_image(image, "mono8", BlobOptions(), WandOptions(), model)
        elapsed = time.process_time() - begin
        rate = repeats * len(images) / elapsed
        print(f"{size[0]}x{size[1]} mono8: {rate:.0f} frames/s per core (CPU time; target >= {target})")


if __name__ == "__main__":
    main()
