"""Thresholds from the local background and its noise: a dim LED on a dark wall is found beside a lamp and
a window, and the window's own noise makes no blobs."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from wand_calib_ros.detection.background import box_sums, box_sums_above, estimate_background
from wand_calib_ros.detection.blobs import BlobOptions, find_blobs
from wand_calib_ros.sim.room import CameraRoom, Lamp, Sensor, Window
from wand_calib_ros.sim.room_images import render_camera

SIZE = (640, 480)


def _room(**kwargs: object) -> CameraRoom:
    sensor = Sensor(exposure_ms=6.0, read_noise=1.5, levels_per_electron=0.25, black_level=2.0)
    return CameraRoom(sensor=sensor, wall_level=1.5, **kwargs)  # type: ignore[arg-type]


def _images(room: CameraRoom, leds: np.ndarray, peak: float, n: int, seed: int) -> list[np.ndarray]:
    """``n`` images of the room with still LEDs at ``leds`` (K, 2) of a given peak (before clipping)."""
    core, sigma = room.optics.terms()[0]
    energy = peak / core * 2 * np.pi * sigma**2
    paths = [np.repeat(leds[:, None, :], 3, axis=1)] * n
    images, _, _, _ = render_camera(
        room, SIZE, paths, [np.full((len(leds), 3), energy / 3)] * n, np.random.default_rng(seed)
    )
    return [np.asarray(image) for image in images]


def test_the_noise_model_follows_the_signal() -> None:
    window = Window((320, 40, 620, 300), 160.0 / 6.0, panes=(2, 2))
    (image,) = _images(_room(windows=(window,)), np.zeros((0, 2)), 0.0, 1, 0)
    background = estimate_background(image)
    wall, pane = background.at(np.array([[100.0, 400.0], [400.0, 100.0]]))[1]
    level = background.at(np.array([[100.0, 400.0], [400.0, 100.0]]))[0]
    expected = np.sqrt(1.5**2 + 0.25 * (level - 2.0) + 1 / 12)  # read, shot above black, quantisation
    # The model is fitted to ~150 tiles of 32 differences each: a few percent; 15 % allows the wall's gradient.
    assert wall == pytest.approx(expected[0], rel=0.15) and pane == pytest.approx(expected[1], rel=0.15)


@pytest.mark.parametrize("seed", range(4))
def test_a_dim_led_beside_a_lamp_and_a_window_is_found_and_noise_makes_no_blobs(seed: int) -> None:
    window = Window((330, 30, 620, 260), 190.0 / 6.0, panes=(2, 2))
    lamps = (Lamp((150.0, 120.0), 4.0, 2000.0), Lamp((500.0, 400.0), 3.0, 1200.0))
    room = _room(windows=(window,), lamps=lamps)
    leds = np.array([[120.3, 300.6], [260.8, 330.1], [300.2, 200.4]])
    images = _images(room, leds, 14.0, 5, seed)  # 14 grey levels: far and turned away
    for image in images:
        blobs = find_blobs(image)
        nearest = np.linalg.norm(blobs.centres[:, None] - leds[None], axis=-1).min(axis=0)
        assert np.all(nearest < 1.0)  # each dim LED found
        others = np.linalg.norm(blobs.centres[:, None] - np.array([lamp.centre for lamp in lamps])[None], axis=-1).min(
            axis=1
        )
        spurious = (np.linalg.norm(blobs.centres[:, None] - leds[None], axis=-1).min(axis=1) > 1.0) & (others > 15)
        assert not spurious.any(), blobs.centres[spurious]  # the window's panes, edges and noise: nothing


def test_the_brightest_pixel_does_not_set_the_threshold() -> None:
    lamp = Lamp((320.0, 240.0), 6.0, 20_000.0)  # far beyond full scale, with a wide glare
    leds = np.array([[100.0, 100.0], [540.0, 400.0]])
    (image,) = _images(_room(lamps=(lamp,)), leds, 12.0, 1, 7)
    blobs = find_blobs(image, BlobOptions())
    assert np.all(np.linalg.norm(blobs.centres[:, None] - leds[None], axis=-1).min(axis=0) < 1.0)


@pytest.mark.parametrize("size", [(1280, 1024), (1283, 1025), (640, 480)])
@pytest.mark.parametrize("depth", [np.uint8, np.uint16])
def test_box_sums_above_a_threshold_are_the_pixels_of_the_whole_images_sums(size: tuple[int, int], depth: type) -> None:
    # a room with lamps, a window and LEDs, of a banded size, an odd one and an unbanded one: the same pixels, bit for
    # bit, as comparing the whole image's box sums (8-bit images' in uint16, 16-bit ones' in float32)
    window = Window((0.55 * size[0], 0.05 * size[1], 0.85 * size[0], 0.3 * size[1]), 30.0)
    room = _room(windows=(window,), lamps=(Lamp((0.15 * size[0], 0.7 * size[1]), 3.0, 900.0),))
    core, sigma = room.optics.terms()[0]
    leds = np.array([[0.2 * size[0], 0.3 * size[1]], [0.5 * size[0], 0.5 * size[1]], [0.8 * size[0], 0.9 * size[1]]])
    paths = [np.repeat(leds[:, None, :], 3, axis=1)] * 2
    energy = [np.full((3, 3), 200.0 / core * 2 * np.pi * sigma**2 / 3)] * 2
    images, _, _, _ = render_camera(room, size, paths, energy, np.random.default_rng(5))
    for image in images:
        gray = np.asarray(image).astype(depth) * (257 if depth == np.uint16 else 1)
        sums, unit = box_sums(gray)
        threshold = estimate_background(sums, unit=unit).threshold
        assert np.array_equal(box_sums_above(gray, threshold), cv2.compare(sums, threshold, cv2.CMP_GT))
