"""The static structure a camera learns from its own images: stripes, grain and reflections are not LEDs, an LED in
front of them is found on its own light, a flickering lamp makes no blob that may be an LED (flecks at its saturated
edge are cut), a driver's repeated image teaches nothing."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from wand_calib_ros.core.model.rig import CameraSpec
from wand_calib_ros.detection.background import box_sums, estimate_background
from wand_calib_ros.detection.recording import CameraStream
from wand_calib_ros.detection.structure import (
    BAND_ROWS,
    MIN_LIGHT_PX,
    QUIET_NS,
    QUIET_SNAPSHOTS,
    SNAPSHOT_NS,
    SNAPSHOTS,
    StaticStructure,
    median_of,
    repeated,
    sorted_pixels,
)
from wand_calib_ros.detection.wand import WandOptions
from wand_calib_ros.sim.room import CameraRoom, Lamp, Reflection, Sensor, Stripe, Window
from wand_calib_ros.sim.room_images import render_camera

SIZE = (320, 240)
FRAME_NS = 33_333_333
#: A centre on a flat field is good to about 0.1 px at these LEDs' contrast: 0.2 px allows the structure's own
#: noise (a median of five images) taken away under it.
CENTRE_PX = 0.2


def test_order_statistics_of_snapshots_are_numpys() -> None:
    rng = np.random.default_rng(0)
    for n in range(1, 6):
        snapshots = [rng.integers(0, 2000, (7, 9)).astype(np.uint16) for _ in range(n)]
        ordered = sorted_pixels(snapshots)
        assert np.array_equal(np.stack(ordered), np.sort(np.stack(snapshots), axis=0))
        assert np.array_equal(median_of(snapshots), np.sort(np.stack(snapshots), axis=0)[(n - 1) // 2])


def test_an_image_sent_twice_teaches_nothing() -> None:
    rng = np.random.default_rng(1)
    sums = (rng.normal(300.0, 6.0, (60, 80))).astype(np.uint16)
    structure = StaticStructure()
    structure.add(0, sums.astype(np.uint8), sums)
    structure.add(60_000_000, sums.astype(np.uint8), sums.copy())  # the same image again: no snapshot, no noise
    assert repeated(sums, sums) and structure.noise is None
    other = (rng.normal(300.0, 6.0, (60, 80))).astype(np.uint16)
    structure.add(120_000_000, other.astype(np.uint8), other)
    assert structure.noise is not None and structure.noise[0] + 300.0 * structure.noise[1] == pytest.approx(
        2 * 36.0, rel=0.35
    )  # (the difference of two images: twice the noise's variance)


def _stream_over(room: CameraRoom, leds: np.ndarray, peak: float, seed: int) -> tuple[list[np.ndarray], CameraStream]:
    """Every image's blob centres that may be an LED (not cut by a saturated light) of one LED at (N, 2) ``leds``
    (a steady ``peak`` grey levels) in ``room``."""
    paths = [np.repeat(p[None, None], 3, axis=1) for p in leds]
    energy = [np.full((1, 3), peak * 2 * np.pi / 3 / 0.9)] * len(leds)
    images, _, _, _ = render_camera(room, SIZE, paths, energy, np.random.default_rng(seed))
    stream = CameraStream(CameraSpec("cam0", SIZE, (5.6, 5.6), 4.0, 40.0), WandOptions())
    found = []
    for k, image in enumerate(images):
        blobs, _, _ = stream.detect(np.asarray(image), "bgr8" if room.sensor.colour else "mono8", k * FRAME_NS)
        assert blobs is not None
        found.append(blobs.centres if blobs.masked is None else blobs.centres[~blobs.masked])
    return found, stream


def _sweep(n: int, seed: int) -> np.ndarray:
    """(n, 2) an LED sweeping to and fro across the image at about 10 px per image."""
    t = np.arange(n) / 30.0
    phase = np.random.default_rng(seed).uniform(0, 2 * np.pi)
    return np.column_stack([160.0 + 120.0 * np.sin(2 * np.pi * 0.4 * t + phase), 120.0 + 60.0 * np.sin(1.3 * t)])


@pytest.mark.parametrize("seed", range(3))
def test_painted_stripes_and_grain_are_no_blobs_and_an_led_crossing_them_is_found_on_its_own_light(seed: int) -> None:
    stripes = (  # a solid line and a dashed one, 30-60 grey levels brighter than a 50-level floor at 12 ms
        Stripe((40.0, 0.0), (120.0, 240.0), 6.0, 60.0 / 12.0),
        *(Stripe((200.0 + 20 * k, 10.0 + 40 * k), (205.0 + 20 * k, 30.0 + 40 * k), 5.0, 30.0 / 12.0) for k in range(5)),
    )
    room = CameraRoom(
        sensor=Sensor(exposure_ms=12.0), wall_level=50.0 / 12.0, stripes=stripes, grain=0.06, grain_seed=seed
    )
    leds = _sweep(150, seed)
    found, _ = _stream_over(room, leds, 40.0, seed)  # an LED 40 grey levels above the floor
    stray, errors = 0, []
    for k in range(15, len(leds)):  # once learned (a structure in a tenth of a second, whole in half a second)
        gaps = np.linalg.norm(found[k] - leds[k], axis=1)
        stray += int((gaps > 4.0).sum())
        errors.append(float(gaps.min()) if gaps.size else np.inf)
    errors_px = np.array(errors)
    assert stray <= 2, stray  # no stripe, dash or grain is a blob
    assert np.mean(errors_px < 1.0) >= 0.97  # the LED found in every image, on the stripes too ...
    assert np.sqrt(np.mean(np.square(errors_px[errors_px < 1.0]))) / np.sqrt(2) < CENTRE_PX  # ... on its own light


@pytest.mark.parametrize("seed", range(3))
def test_an_led_38_grey_levels_above_a_broad_reflection_is_found(seed: int) -> None:
    glow = Reflection((160.0, 120.0), (50.0, 40.0), 110.0 / 12.0)  # a floor at 50 reaching 160
    room = CameraRoom(sensor=Sensor(exposure_ms=12.0), wall_level=50.0 / 12.0, reflections=(glow,), vignetting=0.1)
    t = np.arange(150) / 30.0  # the LED to and fro over the reflection's slopes and top
    leds = np.column_stack([160.0 + 45.0 * np.sin(2.7 * t + seed), 120.0 + 30.0 * np.sin(1.9 * t + 2 * seed)])
    found, _ = _stream_over(room, leds, 38.0, seed)
    hits = [found[k].size > 0 and float(np.linalg.norm(found[k] - leds[k], axis=1).min()) < 1.0 for k in range(15, 150)]
    assert np.mean(hits) >= 0.95


@pytest.mark.parametrize("seed", range(2))
def test_a_flickering_lamp_makes_no_blob_that_may_be_an_led_once_learned(seed: int) -> None:
    lamp = Lamp((100.0, 80.0), 4.0, 1500.0, flicker=0.15)  # mains lamp: +-15 % from image to image
    room = CameraRoom(sensor=Sensor(exposure_ms=6.0), lamps=(lamp,), wall_level=1.5)
    leds = np.tile([[260.0, 200.0]], (90, 1)) + np.arange(90)[:, None] * [[-1.0, 0.0]]  # an LED far from it
    found, _ = _stream_over(room, leds, 200.0, seed)
    near_lamp = [int((np.linalg.norm(c - lamp.centre, axis=1) < 40.0).sum()) if c.size else 0 for c in found[20:]]
    assert sum(near_lamp) <= 2, near_lamp


@pytest.mark.parametrize("shape", [(11, 13), (2 * BAND_ROWS + 7, 13)])  # one band; three, the last one short
def test_the_median_and_the_second_largest_of_five_are_numpys(shape: tuple[int, int]) -> None:
    from wand_calib_ros.detection.structure import median_and_upper

    rng = np.random.default_rng(2)
    for dtype in (np.uint8, np.uint16, np.float32):
        for n in range(3, 6):
            snapshots = [rng.integers(0, 250, shape).astype(dtype) for _ in range(n)]
            median, upper = median_and_upper(snapshots)
            ordered = np.sort(np.stack(snapshots), axis=0)
            assert np.array_equal(median, ordered[(n - 1) // 2]) and np.array_equal(upper, ordered[-2])
            assert np.array_equal(median_of(snapshots), ordered[(n - 1) // 2])


def test_a_still_rooms_snapshots_keep_the_threshold_and_a_lamp_switched_on_makes_it_again() -> None:
    rng = np.random.default_rng(4)
    structure = StaticStructure()
    background = estimate_background(box_sums(np.full((120, 160), 40, np.uint8))[0])

    def snapshot(k: int, lamp: bool = False) -> bool:
        """Whether the snapshot made the structure's threshold again."""
        image = np.clip(rng.normal(40.0, 2.0, (120, 160)), 0, 255).astype(np.uint8)
        if lamp:
            image[50:60, 70:80] = 200
        structure.add(k * SNAPSHOT_NS, image, box_sums(image)[0])
        again = not structure.unchanged
        structure.apply(background)
        return again

    assert all(snapshot(k) for k in range(SNAPSHOTS))  # the window fills: made again with each
    made = [snapshot(k) for k in range(SNAPSHOTS, 3 * SNAPSHOTS)]  # a still room: made again once a window
    assert made == [False] * (SNAPSHOTS - 1) + [True] + [False] * (SNAPSHOTS - 1) + [True]
    assert snapshot(3 * SNAPSHOTS, lamp=True)  # a lamp switched on: its light stands above the threshold


def test_a_still_room_keeps_a_snapshot_every_quiet_interval_and_a_change_at_once() -> None:
    rng = np.random.default_rng(6)
    structure = StaticStructure()
    sums, unit = box_sums(np.clip(rng.normal(40.0, 2.0, (120, 160)), 0, 255).astype(np.uint8))
    background = estimate_background(sums, unit=unit)
    every = QUIET_NS // SNAPSHOT_NS

    def due(k: int, lamp: bool = False, led: tuple[int, int] | None = None, kept_out: bool = False) -> bool:
        """Whether the snapshot due at the k-th SNAPSHOT_NS was kept (an LED at ``led``, in a wand's disc or not)."""
        assert structure.due(k * SNAPSHOT_NS)
        image = np.clip(rng.normal(40.0, 2.0, (120, 160)), 0, 255).astype(np.uint8)
        if lamp:
            image[50:60, 70:80] = 200
        keep_out = []
        if led is not None:
            image[led[1] - 1 : led[1] + 2, led[0] - 1 : led[0] + 2] = 220
            keep_out = [(float(led[0]), float(led[1]), 6.0)] if kept_out else []
        sums = box_sums(image)[0]
        kept = structure.worth_keeping(k * SNAPSHOT_NS, sums, keep_out)
        if kept:
            structure.add(k * SNAPSHOT_NS, image, sums, keep_out)
            structure.apply(background)
        return kept

    k = 0
    while due(k):  # the window fills and stands unchanged through QUIET_SNAPSHOTS: every snapshot kept
        k += 1
    assert SNAPSHOTS <= k <= SNAPSHOTS + QUIET_SNAPSHOTS
    made = structure.structure()
    quiet = [False] + [due(j) for j in range(k + 1, k + 3 * every)]  # still: one kept every QUIET_NS
    assert quiet == ([False] * (every - 1) + [True]) * 3
    k += 3 * every
    assert not due(k, led=(30, 90), kept_out=True)  # the wand passing, in its discs: still
    assert due(k + 1, led=(30, 90))  # a light the wand's discs do not hold: kept at once
    assert due(k + 2, lamp=True)  # a lamp switched on: kept at once, the room no longer still ...
    assert all(due(j, lamp=True) for j in range(k + 3, k + 3 + QUIET_SNAPSHOTS))  # ... until it stands again
    assert made is not None and structure.structure() is not None
    assert np.max(structure.structure()[50:60, 70:80]) > np.max(made[50:60, 70:80])  # the lamp learned


@pytest.mark.parametrize("level", [1.1, 1.2, 1.25])
def test_a_window_just_at_full_scale_is_a_few_lights_not_a_crowd_of_specks(level: float) -> None:
    # panes whose light reaches full scale just: noise leaves their pixels' medians on either side of it, and their
    # saturated pixels fall apart into 15-92 pieces, most of them of one to three pixels
    exposure = 6.0
    room = CameraRoom(
        sensor=Sensor(exposure_ms=exposure),
        lamps=(Lamp((60.0, 190.0), 3.0, 900.0),),
        windows=(Window((150.0, 20.0, 300.0, 100.0), level * 253.0 / exposure),),
    )
    _, stream = _stream_over(room, np.full((60, 2), np.nan), 40.0, 0)
    saturated = stream.structure.saturated(255.0)
    assert saturated is not None
    pieces, _, stats, _ = cv2.connectedComponentsWithStats(saturated.astype(np.uint8), connectivity=8)
    assert pieces - 1 >= 15 and np.sum(stats[1:, cv2.CC_STAT_AREA] < 4) >= 10  # (the crowd is there)
    lights = stream.structure.lights(255.0)
    assert 2 <= len(lights) <= 1 + 4  # the lamp and the window's four panes
    assert min(radius for _, _, radius in lights) >= np.sqrt(MIN_LIGHT_PX / np.pi)
