"""Spot centres: exact for symmetric spots (a saturated flat top with its halo, a streak), the streak's middle
when its brightness changes along it, and on a sloping background."""

from __future__ import annotations

import numpy as np
import pytest

from wand_calib_ros.detection.centres import saturated_centre, spot_centre
from wand_calib_ros.sim.room import CameraRoom, Optics, Sensor
from wand_calib_ros.sim.room_images import render_camera

SIZE = (64, 48)
QUIET = Sensor(read_noise=0.0, levels_per_electron=0.0, black_level=0.0)


def _window(path: np.ndarray, energy: np.ndarray, room: CameraRoom | None = None) -> np.ndarray:
    """The rendered spot of one LED along ``path`` (M, 2), in a 31 x 31 window centred on (32, 24)."""
    room = room or CameraRoom(sensor=QUIET, wall_level=0.0)
    (image,), _, _, _ = render_camera(room, SIZE, [path[None]], [energy[None]], np.random.default_rng(0))
    return np.asarray(image, dtype=np.float64)[9:40, 17:48]


def _error(window: np.ndarray, truth: tuple[float, float], floor: float = 2.0) -> float:
    spot = spot_centre(window, floor)
    assert spot is not None
    return float(np.hypot(spot.u + 17 - truth[0], spot.v + 9 - truth[1]))


@pytest.mark.parametrize("offset", [(0.0, 0.0), (0.3, -0.2), (0.5, 0.45)])
def test_a_saturated_flat_top_with_its_halo_is_centred(offset: tuple[float, float]) -> None:
    truth = (32.0 + offset[0], 24.0 + offset[1])
    window = _window(np.tile(truth, (5, 1)), np.full(5, 60_000.0 / 5))
    assert np.count_nonzero(window == 255) >= 9  # clipped to a flat top
    assert _error(window, truth) < 0.05  # (the rounding of its halo to whole grey levels)


def test_a_streak_is_centred_on_its_mid_exposure_position_or_where_its_light_is() -> None:
    t = np.linspace(-0.5, 0.5, 41)
    path = np.column_stack([32.1 + 14.0 * t, 24.3 + 6.0 * t])  # 15 px long, moving evenly
    even = _window(path, np.full(41, 3000.0 / 41))
    assert _error(even, (32.1, 24.3)) < 0.05
    spot = spot_centre(even, 2.0)
    assert spot is not None and spot.length_px == pytest.approx(np.hypot(14.0, 6.0), abs=0.5)
    brightening = _window(path, (1.0 + 0.6 * t) * 3000.0 / 41)  # 60 % brighter at its end than at its start
    weighted = np.sum(path * (1.0 + 0.6 * t)[:, None], axis=0) / np.sum(1.0 + 0.6 * t)  # the light's mean
    assert _error(brightening, tuple(weighted)) < 0.08  # (g L / 12 = 0.8 px from mid-exposure: documented)


def test_a_spot_on_a_sloping_background_is_centred() -> None:
    # the wall from 5 to 15 grey levels across the image
    room = CameraRoom(sensor=QUIET, wall_level=10.0 / 6.0, wall_gradient=(1.0, 0.8), vignetting=0.0)
    window = _window(np.tile((32.2, 23.9), (5, 1)), np.full(5, 600.0 / 5), room)
    assert _error(window, (32.2, 23.9), floor=1.0) < 0.05


def _saturated_error(window: np.ndarray, truth: tuple[float, float], static: np.ndarray | None = None) -> float:
    """The outline centre's error of the saturated spot in a window (the static light under it taken away)."""
    under = np.zeros_like(window) if static is None else static
    spot = saturated_centre(window - under, 0.0, float(np.min(255.0 - under[window >= 255])))
    return float(np.hypot(spot.u + 17 - truth[0], spot.v + 9 - truth[1]))


@pytest.mark.parametrize("offset", [(0.0, 0.0), (0.3, -0.2), (0.5, 0.45)])
def test_a_deeply_saturated_spot_with_a_wide_bloom_is_centred_by_its_outline(offset: tuple[float, float]) -> None:
    truth = (32.0 + offset[0], 24.0 + offset[1])
    blooming = CameraRoom(sensor=QUIET, wall_level=0.0, optics=Optics(1.0, (0.25, 8.0), (0.06, 20.0)))
    # 30x over full scale: a flat top 5 px across, its bloom 60 grey levels beside it, its halo beyond the window
    window = _window(np.tile(truth, (5, 1)), np.full(5, 30 * 255 * 2 * np.pi / 5 / 0.69), blooming)
    assert np.count_nonzero(window == 255) >= 20 and window[0].max() > 5  # a flat top, a halo past the sides
    assert _saturated_error(window, truth) < 0.05


def test_a_saturated_spot_across_a_bright_edge_is_centred_where_the_light_weighted_mean_is_not() -> None:
    truth = (34.2, 24.3)
    quiet = CameraRoom(sensor=QUIET, wall_level=0.0)
    (edge,), _, _, _ = render_camera(  # the room: a bright unsaturated region (180) right of u = 34.5
        quiet, SIZE, [np.zeros((0, 1, 2))], [np.zeros((0, 1))], np.random.default_rng(0)
    )
    static = np.zeros((SIZE[1], SIZE[0]))
    static[:, 35:] = 180.0
    window = _window(np.tile(truth, (5, 1)), np.full(5, 40_000.0 / 5)) + static[9:40, 17:48]
    window = np.minimum(window, 255.0)
    assert np.asarray(edge).max() == 0
    # the light-weighted mean over the room's light is pulled by the edge; the outline clipped at the least
    # headroom under the spot is not
    assert _error(window - static[9:40, 17:48], truth) > 0.2
    assert _saturated_error(window, truth, static[9:40, 17:48]) < 0.06
