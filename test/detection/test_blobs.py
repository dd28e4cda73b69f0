"""Blob extraction: sub-pixel centres, encodings, and images without a wand."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from wand_calib_ros.detection.background import box_sums, estimate_background, masked
from wand_calib_ros.detection.blobs import _clear_outline, external_contours, find_blobs, to_gray
from wand_calib_ros.detection.centres import saturated_centre
from wand_calib_ros.detection.errors import ImageError
from wand_calib_ros.detection.masks import mask_from_shapes
from wand_calib_ros.sim.render import RenderOptions, render_image


def _spots(rng: np.random.Generator, n: int = 3) -> np.ndarray:
    return np.column_stack([rng.uniform(40, 600, n), rng.uniform(40, 440, n)])


def test_centres_are_sub_pixel_accurate_at_realistic_noise() -> None:
    rng = np.random.default_rng(0)
    errors = []
    for _ in range(200):
        spots = _spots(rng)
        if np.min([np.linalg.norm(a - b) for i, a in enumerate(spots) for b in spots[i + 1 :]]) < 20:
            continue
        blobs = find_blobs(to_gray(render_image((640, 480), spots, RenderOptions(), rng), "mono8"))
        assert blobs.centres.shape == (3, 2)
        for spot in spots:
            errors.append(np.min(np.linalg.norm(blobs.centres - spot, axis=1)))
    assert np.sqrt(np.mean(np.square(errors))) < 0.15


@pytest.mark.parametrize("encoding", ["mono16", "bgr8", "rgb8", "bayer_rggb8"])
def test_other_encodings_give_the_same_centres(encoding: str) -> None:
    rng = np.random.default_rng(1)
    spots = np.array([[100.3, 200.7], [300.5, 220.2], [500.1, 240.9]])
    mono = render_image((640, 480), spots, RenderOptions(read_noise=0.0), rng)
    if encoding == "mono16":
        image = mono.astype(np.uint16) * 256
    elif encoding == "bayer_rggb8":
        image = mono  # a grey scene looks the same through any Bayer pattern
    else:
        image = cv2.cvtColor(mono, cv2.COLOR_GRAY2BGR)
    saturation = 65535.0 if encoding == "mono16" else 255.0
    blobs = find_blobs(to_gray(image, encoding), saturation=saturation)
    assert blobs.centres.shape == (3, 2)
    reference = find_blobs(to_gray(mono, "mono8")).centres
    assert np.allclose(np.sort(blobs.centres, axis=0), np.sort(reference, axis=0), atol=0.3)


def test_noise_only_and_saturated_images_give_no_wand_blobs() -> None:
    rng = np.random.default_rng(2)
    noise = np.clip(rng.normal(20, 3, size=(480, 640)), 0, 255).astype(np.uint8)
    assert find_blobs(to_gray(noise, "mono8")).centres.shape[0] == 0
    white = np.full((480, 640), 255, dtype=np.uint8)
    assert find_blobs(to_gray(white, "mono8")).centres.shape[0] == 0


def test_unusable_images_raise_image_errors() -> None:
    with pytest.raises(ImageError, match="unsupported image encoding 'yuv422'"):
        to_gray(np.zeros((4, 4), np.uint8), "yuv422")
    with pytest.raises(ImageError, match="does not match encoding 'bgr8'"):
        to_gray(np.zeros((4, 4), np.uint8), "bgr8")
    with pytest.raises(ImageError, match="empty image"):
        to_gray(np.zeros((0, 0), np.uint8), "mono8")


def test_a_spot_cut_by_the_image_border_is_marked() -> None:
    rng = np.random.default_rng(5)
    spots = np.array([[0.4, 200.0], [320.0, 200.0], [639.2, 300.0], [320.0, 479.5], [100.0, 100.0]])
    blobs = find_blobs(to_gray(render_image((640, 480), spots, RenderOptions(), rng), "mono8"))
    assert blobs.at_border is not None and blobs.centres.shape == (5, 2)
    near = [int(np.argmin(np.linalg.norm(blobs.centres - spot, axis=1))) for spot in spots]
    assert blobs.at_border[near].tolist() == [True, False, True, True, False]
    assert blobs.centres[near[0], 0] > 0.4 + 0.3  # what a cut spot does to its centre: pulled inwards


@pytest.mark.parametrize("encoding", ["mono8", "mono16"])
def test_a_mask_held_in_the_background_finds_what_the_mask_itself_finds(encoding: str) -> None:
    # A stream puts its mask into the background's search threshold once; the blobs are those of the mask applied
    # to the image: the masked spots gone, a spot the mask touches marked.
    rng = np.random.default_rng(5)
    spots = np.array([[100.3, 200.7], [300.5, 220.2], [500.1, 240.9], [320.0, 400.0]])
    mono = render_image((640, 480), spots, RenderOptions(), rng)
    gray = to_gray(mono.astype(np.uint16) * 257 if encoding == "mono16" else mono, encoding)
    mask = mask_from_shapes((640, 480), circles=[(500.0, 241.0, 8.0), (324.0, 400.0, 3.0)])
    sums, unit = box_sums(gray)
    background = estimate_background(sums, unit=unit)
    applied = find_blobs(gray, mask=mask, background=background)
    held = find_blobs(gray, mask=mask, background=masked(background, mask))
    assert applied.centres.shape[0] == 3 and not np.any(np.linalg.norm(applied.centres - spots[2], axis=1) < 5)
    assert np.array_equal(held.centres, applied.centres) and np.array_equal(held.masked, applied.masked)
    assert applied.masked is not None and applied.masked.sum() == 1  # the spot beside the small circle
    alone = find_blobs(gray, background=masked(background, mask))  # the threshold alone keeps the masked spot out
    assert alone.centres.shape[0] == 3 and not np.any(np.linalg.norm(alone.centres - spots[2], axis=1) < 5)


def test_a_saturated_spots_outline_rises_to_stay_clear_of_a_saturated_light_beside_it() -> None:
    # a spot 8x over its headroom (sigma 2 px) and, 6.7 px from its centre, a saturated light's edge: the outline at
    # an eighth of the headroom (5.8 px) and a pixel around it reach it, at a quarter (5.3 px) not; its centre,
    # measured there, is the true one
    ceiling, size, centre = 200.0, 41, np.array([20.3, 20.6])
    rows, cols = np.mgrid[0:size, 0:size]
    light = np.minimum(8.0 * ceiling * np.exp(-((cols - centre[0]) ** 2 + (rows - centre[1]) ** 2) / 8.0), ceiling)
    seen = light > 1.0
    visible = np.ones((size, size), dtype=bool)
    visible[:, int(centre[0]) + 7 :] = False  # the light's saturated pixels
    seen &= visible
    least, cut = _clear_outline(light, ceiling, 4.0, seen, visible)
    assert not cut and least == pytest.approx(0.25 * ceiling)
    spot = saturated_centre(light, 0.0, ceiling, seen, least)
    assert np.hypot(spot.u - centre[0], spot.v - centre[1]) < 0.02
    assert _clear_outline(light, ceiling, 4.0, seen, None) == (4.0, False)  # (nothing saturated near: as it was)
    visible[:, int(centre[0]) + 3 :] = False  # the light over its core: cut whatever the outline
    assert _clear_outline(light, ceiling, 4.0, seen & visible, visible)[1]


@pytest.mark.parametrize("size", [(1280, 1024), (640, 480)])
@pytest.mark.parametrize("seed", range(3))
def test_external_contours_are_opencvs_in_its_order(seed: int, size: tuple[int, int]) -> None:
    # rendered spots, some close enough to share rows, and pixels on the image's borders: the contours of the runs of
    # occupied rows are those of the whole image, in its order, point for point
    rng = np.random.default_rng(seed)
    width, height = size
    spots = np.column_stack([rng.uniform(0, width - 1, 12), rng.uniform(0, height - 1, 12)])
    image = render_image(size, spots, RenderOptions(), rng)
    sums, unit = box_sums(image)
    above = cv2.compare(sums, estimate_background(sums, unit=unit).threshold, cv2.CMP_GT)
    above[0, 5:9] = above[-1, 100:103] = above[400:403, -1] = 255
    expected, _ = cv2.findContours(above, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    found = external_contours(above)
    assert len(found) == len(expected) >= 12
    assert all(np.array_equal(a, b) for a, b in zip(found, expected, strict=True))


def test_external_contours_of_an_image_lit_in_most_rows_are_opencvs() -> None:
    # a speckled image (pixels in most rows: scanned whole) gives OpenCV's contours too
    rng = np.random.default_rng(5)
    above = np.where(rng.random((480, 640)) > 0.995, 255, 0).astype(np.uint8)
    expected, _ = cv2.findContours(above, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    found = external_contours(above)
    assert len(found) == len(expected) > 100
    assert all(np.array_equal(a, b) for a, b in zip(found, expected, strict=True))
