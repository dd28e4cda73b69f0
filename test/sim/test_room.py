"""The room renderer draws what its docstring says: light conserved through the optics, streaks centred on
mid-exposure, clipping at full scale, noise growing with the signal, the encodings a camera sends."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest
from scipy.special import erf

from wand_calib_ros.io.images import decode_compressed
from wand_calib_ros.sim.room import (
    CameraRoom,
    CameraTruth,
    Lamp,
    Optics,
    Sensor,
    Window,
    clearly_visible,
)
from wand_calib_ros.sim.room_images import render_camera

SIZE = (160, 120)


def _still(position: tuple[float, float], energy: float, steps: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """One LED (K = 1) standing at ``position`` over the exposure."""
    return np.tile(np.array(position), (1, steps, 1)), np.full((1, steps), energy / steps)


def _dark() -> CameraRoom:
    """A noise-free camera seeing nothing but its LEDs."""
    return CameraRoom(sensor=Sensor(read_noise=0.0, levels_per_electron=0.0, black_level=0.0), wall_level=0.0)


def test_the_optics_keep_an_leds_light_and_spread_it_as_their_terms_say() -> None:
    path, energy = _still((80.3, 60.6), 1000.0)  # below full scale
    (image,), _, _, _ = render_camera(_dark(), SIZE, [path], [energy], np.random.default_rng(0))
    pixels = np.asarray(image, dtype=np.float64)
    assert abs(pixels.sum() - 1000.0) < 0.3 * np.sqrt(pixels.size)  # all of it, but for rounding to whole levels
    rows, cols = np.mgrid[: SIZE[1], : SIZE[0]]
    assert abs((pixels * cols).sum() / pixels.sum() - 80.3) < 0.02
    assert abs((pixels * rows).sum() / pixels.sum() - 60.6) < 0.02
    path, energy = _still((80.0, 60.0), 1000.0)  # on a pixel's centre: its share of each Gaussian term
    _, _, peaks, _ = render_camera(_dark(), SIZE, [path], [energy], np.random.default_rng(0))
    share = sum(fraction * erf(0.5 / (np.sqrt(2) * sigma)) ** 2 for fraction, sigma in Optics().terms())
    assert peaks[0, 0] == pytest.approx(1000.0 * share, rel=1e-6)


def test_a_streak_is_centred_on_its_mid_exposure_position_and_a_bright_spot_clips_flat() -> None:
    steps = np.linspace(-6.0, 6.0, 25)
    path = np.stack([80.2 + steps, 60.0 + 0.5 * steps], axis=-1)[None]
    (image,), _, _, _ = render_camera(_dark(), SIZE, [path], [np.full((1, 25), 400.0)], np.random.default_rng(0))
    pixels = np.asarray(image, dtype=np.float64)
    rows, cols = np.mgrid[: SIZE[1], : SIZE[0]]
    assert (
        abs((pixels * cols).sum() / pixels.sum() - 80.2) < 0.02
        and abs((pixels * rows).sum() / pixels.sum() - 60.0) < 0.02
    )
    path, energy = _still((80.0, 60.0), 200_000.0)
    (image,), _, _, _ = render_camera(_dark(), SIZE, [path], [energy], np.random.default_rng(0))
    assert int(np.count_nonzero(np.asarray(image) == 255)) >= 9  # a flat top, not a single pixel


def test_the_noise_grows_with_the_signal() -> None:
    sensor = Sensor(read_noise=1.5, levels_per_electron=0.25, black_level=10.0)  # (no clipping at 0)
    quiet = Sensor(read_noise=0.0, levels_per_electron=0.0, black_level=10.0)
    dark = CameraRoom(sensor=sensor, wall_level=2.0 / sensor.exposure_ms)
    window = Window((0, 0, SIZE[0] - 1, SIZE[1] - 1), 150.0 / sensor.exposure_ms, panes=(1, 1))
    bright = CameraRoom(sensor=sensor, wall_level=0.0, windows=(window,))
    rng = np.random.default_rng(0)
    nothing = ([np.zeros((0, 1, 2))] * 2, [np.zeros((0, 1))] * 2)
    for room in (dark, bright):
        images, _, _, _ = render_camera(room, SIZE, *nothing, rng)
        (signal, _), _, _, _ = render_camera(replace(room, sensor=quiet), SIZE, *nothing, rng)
        a, b = (np.asarray(image, dtype=np.float64)[20:-20, 20:-20] for image in images)
        level = np.asarray(signal, dtype=np.float64)[20:-20, 20:-20] - 10.0
        measured = np.var(a - b) / 2  # two images of the same light: only the noise differs
        expected = np.mean(1.5**2 + 0.25 * level + 1 / 12)  # read, shot, quantisation
        # the variance of 2 x 9,600 samples is known to sqrt(2 / 9,600) = 1.4 %; 6 % is four of those
        assert measured == pytest.approx(expected, rel=0.06), (float(level.mean()), measured, expected)


@pytest.mark.parametrize("encoding", ["mono16", "bayer_rggb8", "bgr8", "jpeg"])
def test_the_encodings_a_camera_sends(encoding: str) -> None:
    jpeg = encoding == "jpeg"
    sensor = Sensor(
        read_noise=0.0,
        levels_per_electron=0.0,
        black_level=0.0,
        encoding="bgr8" if jpeg else encoding,
        jpeg_quality=85 if jpeg else None,
    )
    room = CameraRoom(sensor=sensor, wall_level=0.0, led_colour=(1.0, 0.0, 0.0))  # a red LED
    path, energy = _still((80.0, 60.0), 2000.0)
    lamp = CameraRoom(sensor=sensor, wall_level=0.0, lamps=(Lamp((30.0, 30.0), 3.0, 5000.0),))
    (image,), sent, _, _ = render_camera(room, SIZE, [path], [energy], np.random.default_rng(0))
    if encoding == "mono16":
        assert sent == "mono16" and image.dtype == np.uint16 and np.all(np.asarray(image) % 16 == 0)
        (lit,), _, _, _ = render_camera(lamp, SIZE, [np.zeros((0, 1, 2))], [np.zeros((0, 1))], np.random.default_rng(0))
        assert int(np.asarray(lit).max()) == 4095 * 16  # a 12-bit camera's full scale, in the top of 16 bits
    elif encoding == "bayer_rggb8":
        mosaic = np.asarray(image)
        assert mosaic[60, 80] > 100 and mosaic[61, 81] == 0  # red at even rows and columns, blue at odd ones
    elif encoding == "bgr8":
        pixel = np.asarray(image)[60, 80]
        assert pixel[2] > 100 and pixel[0] < 20  # demosaiced: red, not blue
    else:
        assert isinstance(image, bytes) and sent == "bgr8; jpeg compressed bgr8"
        grey, decoded = decode_compressed(image, sent)
        reference = cv2.cvtColor(np.full((1, 1, 3), (0, 0, 255), np.uint8), cv2.COLOR_BGR2GRAY)[0, 0]
        assert decoded == "mono8" and grey.shape == (SIZE[1], SIZE[0]) and grey[60, 80] > 0.5 * reference


def test_a_clearly_visible_view_is_bright_clear_of_lamps_inside_and_spread_out() -> None:
    uv = np.array([[[20.0, 20.0], [60.0, 20.0], [80.0, 20.0]]] * 6)
    contrast = np.full((6, 3), 50.0)
    noise = np.full((6, 3), 2.0)
    light = np.zeros((6, 3))
    near = np.zeros((6, 3), dtype=bool)
    uv[1, 0] = [3.0, 20.0]  # too near the border
    contrast[2, 1] = 8.0  # too dim
    light[3, 2] = 30.0  # on a lamp's halo
    near[4, 0] = True  # beside a lamp
    uv[5, 2] = [70.0, 20.0]  # 10 px from B
    truth = CameraTruth("cam0", np.arange(6), uv, contrast, noise, light, near, np.zeros((6, 3)), SIZE)
    assert clearly_visible(truth).tolist() == [True, False, False, False, False, False]
