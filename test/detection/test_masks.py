"""Masks: lights that stay put are learned and masked (never the wand's LEDs, moving or laid down), their halos
subtracted so that an LED passing close is found; a mask from the rig file or taken from the view."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from wand_calib_ros.core.model.rig import CameraSpec
from wand_calib_ros.detection.blobs import Blobs
from wand_calib_ros.detection.errors import MaskError
from wand_calib_ros.detection.masks import (
    STATIC_FORGET_S,
    STATIC_LEARN_S,
    MaskTaker,
    StaticSources,
    mask_from_shapes,
    mask_of,
    read_mask,
)
from wand_calib_ros.detection.recording import CameraStream
from wand_calib_ros.detection.wand import WandOptions
from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.rig_yaml import load_camera_masks
from wand_calib_ros.sim.room import CameraRoom, Lamp, Sensor
from wand_calib_ros.sim.room_images import render_camera

SIZE = (320, 240)
FRAME_NS = 33_333_333


def _blobs(points: list[tuple[float, float]]) -> Blobs:
    n = len(points)
    return Blobs(np.array(points, dtype=float).reshape(n, 2), np.full(n, 20, np.int64), np.ones(n), np.zeros(n, bool))


def test_a_light_that_stays_is_learned_and_masked_and_forgotten_once_gone() -> None:
    sources = StaticSources(SIZE)
    images = int(STATIC_LEARN_S * 30) + 5
    for k in range(images):
        moving = (20.0 + 4.0 * k, 200.0)  # a moving LED: never a source
        sources.observe(k * FRAME_NS, _blobs([(100.0, 50.0), moving]), np.zeros(2, bool))
    assert [s.centre for s in sources.sources] == [(100.0, 50.0)]
    assert sources.mask[50, 100] == 255 and sources.mask[200, 60] == 0
    assert sources.still(_blobs([(100.4, 50.2), (250.0, 10.0)])).tolist() == [True, False]
    k = images
    while k * FRAME_NS < (images + STATIC_FORGET_S * 30 + 2) * FRAME_NS:  # the light is switched off
        sources.observe(k * FRAME_NS, _blobs([]), np.zeros(0, bool), np.array([False] * len(sources.sources)))
        k += 1
    assert not sources.sources and not sources.mask.any()


def test_the_wands_leds_laid_down_are_never_learned() -> None:
    sources = StaticSources(SIZE)
    for k in range(int(3 * STATIC_LEARN_S * 30)):  # the wand's track holds them: they are claimed
        sources.observe(k * FRAME_NS, _blobs([(100.0, 50.0), (150.0, 60.0)]), np.ones(2, bool), None, 0)
    assert not sources.sources and not sources.still(_blobs([(100.0, 50.0)])).any()


@pytest.mark.parametrize("seed", range(2))
def test_an_led_passing_close_to_a_lamp_is_found_once_its_halo_is_learned(seed: int) -> None:
    rng = np.random.default_rng(seed)
    lamp = Lamp((160.0, 120.0), 3.0, 1500.0, flicker=0.1)  # far beyond full scale: a halo tens of px wide
    room = CameraRoom(sensor=Sensor(exposure_ms=6.0), lamps=(lamp,), wall_level=1.5)
    n = 300  # 10 s: an LED sweeping to and fro, passing the lamp 12-20 px away twice a second
    phase = rng.uniform(0, 2 * np.pi)
    t = np.arange(n) / 30.0
    leds = np.column_stack([160.0 + 140.0 * np.sin(2 * np.pi * 0.5 * t + phase), 120.0 + 16.0 + 4 * np.sin(t)])
    paths = [np.repeat(p[None, None], 3, axis=1) for p in leds]
    energy = [np.full((1, 3), 400.0 * 2 * np.pi / 3)] * n  # a 400 grey level LED (saturating)
    images, _, _, _ = render_camera(room, SIZE, paths, energy, rng)
    stream = CameraStream(CameraSpec("cam0", SIZE, (5.6, 5.6), 4.0, 40.0), WandOptions())
    errors = []
    for k, (image, led) in enumerate(zip(images, leds, strict=True)):
        blobs, _, _ = stream.detect(np.asarray(image), "mono8", k * FRAME_NS)
        assert blobs is not None
        if k * FRAME_NS >= 5e9 and np.linalg.norm(led - lamp.centre) < 25.0:  # close to the lamp, its halo learned
            assert stream.structure.structure() is not None
            found = np.linalg.norm(blobs.centres - led, axis=1) if blobs.centres.size else np.array([np.inf])
            errors.append(float(found.min()))
    errors_px = np.array(errors)
    assert errors_px.size >= 10 and np.mean(errors_px < 0.5) >= 0.95, errors_px  # found, on its own light


def test_masks_from_shapes_files_and_the_rig_file(tmp_path: Path) -> None:
    mask = mask_from_shapes(SIZE, [(50.0, 60.0, 5.0)], [(200.0, 10.0, 220.0, 30.0)])
    assert mask[60, 50] == 255 and mask[20, 210] == 255 and mask[100, 100] == 0
    cv2.imwrite(str(tmp_path / "cam0.png"), mask)
    assert np.array_equal(read_mask(tmp_path / "cam0.png", SIZE), mask)
    with pytest.raises(MaskError, match=r"a 320x240 mask for a 640x480 camera"):
        read_mask(tmp_path / "cam0.png", (640, 480))
    (tmp_path / "notes.txt").write_text("no image")
    with pytest.raises(MaskError, match="not an image file"):
        read_mask(tmp_path / "notes.txt", SIZE)
    rig = """wand: {L1: 400, L2: 200}
cameras:
  - {name: cam0, image_size: [320, 240], pixel_size_um: [5.6, 5.6], nominal_focal_mm: 4, max_view_angle_deg: 40,
     mask: {circles: [[100, 100, 8]], file: cam0.png}}
  - {name: cam1, image_size: [320, 240], pixel_size_um: [5.6, 5.6], nominal_focal_mm: 4, max_view_angle_deg: 40}
"""
    (tmp_path / "cameras.yaml").write_text(rig)
    specs = load_camera_masks(tmp_path / "cameras.yaml")
    assert list(specs) == ["cam0"]
    combined = mask_of(specs["cam0"], SIZE)
    assert combined[100, 100] == 255 and combined[60, 50] == 255 and combined[200, 300] == 0
    for bad, message in (
        ("mask: {circles: [[100, 100]]}", "each entry has 3 numbers"),
        ("mask: {circles: [[100, 100, -2]]}", "a radius must be positive"),
        ("mask: {rectangles: [[10, 10, 5, 20]]}", "u0 <= u1"),
        ("mask: missing.png", "no such file"),
        ("mask: {lamps: []}", "must be a PNG file name or a mapping"),
    ):
        (tmp_path / "bad.yaml").write_text(rig.replace("mask: {circles: [[100, 100, 8]], file: cam0.png}", bad))
        with pytest.raises(FormatError, match=message):
            load_camera_masks(tmp_path / "bad.yaml")


def test_a_mask_taken_from_the_view_ignores_its_lights_from_then_on() -> None:
    rng = np.random.default_rng(3)
    room = CameraRoom(sensor=Sensor(exposure_ms=6.0), lamps=(Lamp((80.0, 60.0), 2.5, 800.0),), wall_level=1.5)
    nothing = [np.zeros((0, 3, 2))] * 40
    images, _, _, _ = render_camera(room, SIZE, nothing, [np.zeros((0, 3))] * 40, rng)
    stream = CameraStream(CameraSpec("cam0", SIZE, (5.6, 5.6), 4.0, 40.0), WandOptions())
    stream.take_mask(int(0.5e9))
    reasons = [stream.detect(np.asarray(image), "mono8", k * FRAME_NS)[2] for k, image in enumerate(images)]
    assert reasons[:15] == ["taking_mask"] * 15 + [] and not stream.taking_mask
    assert stream.taken is not None and stream.taken[60, 80] == 255 and stream.mask is not None
    blobs, _, _ = stream.detect(np.asarray(images[-1]), "mono8", 40 * FRAME_NS)
    assert blobs is not None and not blobs.centres.size  # the lamp is ignored
    taker = MaskTaker(SIZE)
    taker.add(_blobs([(10.0, 10.0)]))
    assert taker.images == 1 and taker.mask[10, 10] == 255


def test_the_debug_picture_outlines_the_mask() -> None:
    from wand_calib_ros.detection.overlay import draw_overlay

    mask = mask_from_shapes(SIZE, circles=[(100.0, 80.0, 12.0)], rectangles=[])
    picture = draw_overlay(np.full(SIZE[::-1], 40, np.uint8), "mono8", None, None, "no_blobs", mask)
    magenta = np.all(picture == (255, 0, 255), axis=2)
    v, u = np.nonzero(magenta)
    assert magenta.sum() > 50 and np.hypot(u - 100, v - 80).max() <= 13.5 and np.hypot(u - 100, v - 80).min() >= 10
