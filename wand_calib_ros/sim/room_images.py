"""The room renderer's picture: lights through the optics, the static scene, the sensor's noise and encoding.

Pure image kernels on numpy arrays (:mod:`wand_calib_ros.sim.room` holds the records they draw).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.special import erf

from wand_calib_ros.io.images import encode_compressed
from wand_calib_ros.sim.room import CameraRoom, Optics, Stripe, Window

FloatArray = NDArray[np.float64]

#: Colour encodings rendered through a Bayer mosaic (RGGB) and OpenCV's demosaicing.
_DEMOSAIC = {"bgr8": cv2.COLOR_BayerRGGB2BGR, "rgb8": cv2.COLOR_BayerRGGB2RGB}
#: Rec. 601 luma of an RGB colour (what a grey conversion of a colour image sees).
_LUMA = np.array([0.299, 0.587, 0.114])


def _pixel_gaussian(centres: FloatArray, start: int, size: int, sigma: float) -> FloatArray:
    """(M, size) the share of a unit 1D Gaussian at each of M ``centres`` that falls in pixels start..start+size-1."""
    edges = np.arange(start, start + size + 1) - 0.5
    cdf = 0.5 * (1.0 + erf((edges[None, :] - centres[:, None]) / (np.sqrt(2.0) * sigma)))
    return np.diff(cdf, axis=1)


def _spread(
    path: FloatArray, energy: FloatArray, optics: Optics, size: tuple[int, int], radius: float = 0.0
) -> tuple[FloatArray, int, int]:
    """A light moving along ``path`` through the optics, as a patch of the image.

    Args:
        path: (M, 2) its positions over the exposure (equal time steps), px.
        energy: (M,) the light of each step (grey levels x px).
        optics: the point spread.
        size: the image's (width, height).
        radius: the light is a glowing disc this wide (px; 0: a point): under the sharp core it is spread over
            the disc (:func:`_glowing_disc`), the wide terms see it as a point (a disc of r px under a Gaussian of sigma
            px is that Gaussian to (r / sigma)^2).

    Returns:
        The (h, w) patch and its top-left pixel (u0, v0).
    """
    reach = 4.0 * max(sigma for _, sigma in optics.terms()) + radius
    u0 = max(int(np.floor(path[:, 0].min() - reach)), 0)
    v0 = max(int(np.floor(path[:, 1].min() - reach)), 0)
    u1 = min(int(np.ceil(path[:, 0].max() + reach)), size[0] - 1)
    v1 = min(int(np.ceil(path[:, 1].max() + reach)), size[1] - 1)
    if u1 < u0 or v1 < v0:
        return np.zeros((0, 0)), 0, 0
    patch = np.zeros((v1 - v0 + 1, u1 - u0 + 1))
    for k, (fraction, sigma) in enumerate(optics.terms()):
        points, light = _glowing_disc(path, energy, radius) if k == 0 else (path, energy)
        gx = _pixel_gaussian(points[:, 0], u0, u1 - u0 + 1, sigma)
        gy = _pixel_gaussian(points[:, 1], v0, v1 - v0 + 1, sigma)
        patch += fraction * (gy * light[:, None]).T @ gx
    return patch, u0, v0


def _glowing_disc(centres: FloatArray, energy: FloatArray, radius: float) -> tuple[FloatArray, FloatArray]:
    """A glowing disc instead of a point: each of the (M, 2) positions (energy (M,)) spread over D points filling a
    disc of ``radius`` px evenly (a sunflower pattern, about two per px^2), each with 1/D of the light:
    (M * D, 2) and (M * D,)."""
    count = int(np.clip(np.ceil(2.0 * np.pi * radius**2), 1, 200)) if np.isfinite(radius) else 1
    if count == 1:
        return centres, energy
    index = np.arange(count) + 0.5
    angle = 2.39996323 * index  # (the golden angle: no two points in line)
    spiral = radius * np.sqrt(index / count)[:, None] * np.stack([np.cos(angle), np.sin(angle)], axis=-1)
    points = (centres[:, None, :] + spiral[None]).reshape(-1, 2)
    return points, np.repeat(energy / count, count)


def _bayer_gain(colour: tuple[float, float, float], shape: tuple[int, int], origin: tuple[int, int]) -> FloatArray:
    """(h, w) each pixel's response to a colour through an RGGB mosaic whose patch starts at ``origin`` (u, v)."""
    rows = (np.arange(shape[0]) + origin[1]) % 2
    cols = (np.arange(shape[1]) + origin[0]) % 2
    channel = np.where(rows[:, None] == 0, np.where(cols[None, :] == 0, 0, 1), np.where(cols[None, :] == 0, 1, 2))
    return np.asarray(colour, dtype=np.float64)[channel]


def _response(
    room: CameraRoom, colour: tuple[float, float, float], patch: FloatArray, origin: tuple[int, int]
) -> FloatArray:
    """A light's patch as the sensor records it: through the mosaic for colour cameras, else as its luma."""
    if room.sensor.colour:
        return patch * _bayer_gain(colour, patch.shape, origin)
    return patch * float(_LUMA @ np.asarray(colour))


def _blurred(image: FloatArray, optics: Optics) -> FloatArray:
    """An image of sharp lights through the optics."""
    out = np.zeros_like(image)
    for fraction, sigma in optics.terms():
        out += fraction * cv2.GaussianBlur(image, (0, 0), sigma, borderType=cv2.BORDER_REFLECT)
    return out


def _disc(size: tuple[int, int], centre: tuple[float, float], radius: float) -> FloatArray:
    """(H, W) coverage (0..1, 4x4 samples per pixel) of a disc."""
    width, height = size
    image = np.zeros((height, width))
    u0, u1 = max(int(centre[0] - radius - 2), 0), min(int(centre[0] + radius + 3), width)
    v0, v1 = max(int(centre[1] - radius - 2), 0), min(int(centre[1] + radius + 3), height)
    sub = (np.arange(4) + 0.5) / 4 - 0.5
    us = (np.arange(u0, u1)[:, None] + sub[None, :]).reshape(-1)
    vs = (np.arange(v0, v1)[:, None] + sub[None, :]).reshape(-1)
    inside = (us[None, :] - centre[0]) ** 2 + (vs[:, None] - centre[1]) ** 2 <= radius**2
    image[v0:v1, u0:u1] = inside.reshape(v1 - v0, 4, u1 - u0, 4).mean(axis=(1, 3))
    return image


def _panes(size: tuple[int, int], window: Window) -> FloatArray:
    """(H, W) coverage of a window's panes (bars excluded), with a gentle gradient of the sky across it."""
    width, height = size
    u0, v0, u1, v1 = window.box
    us, vs = np.arange(width)[None, :], np.arange(height)[:, None]
    inside = (us >= u0) & (us <= u1) & (vs >= v0) & (vs <= v1)
    columns, rows = window.panes
    for i in range(1, columns):
        bar = u0 + i * (u1 - u0) / columns
        inside &= np.abs(us - bar) > window.bar_px / 2
    for j in range(1, rows):
        bar = v0 + j * (v1 - v0) / rows
        inside &= np.abs(vs - bar) > window.bar_px / 2
    sky = 1.0 - 0.25 * (vs - v0) / max(v1 - v0, 1.0)
    return np.where(inside, sky, 0.0)


@dataclass(frozen=True, eq=False)
class _Scene:
    """A camera's static picture per ms, sensor-side (mosaic gains applied): the wall, the windows, and each lamp
    as a patch (it flickers on its own)."""

    wall: FloatArray
    windows: FloatArray
    lamps: tuple[tuple[FloatArray, int, int], ...]
    luma_light: FloatArray  # the lamps' and windows' light (luma) per ms, for the truth


def _stripe(size: tuple[int, int], stripe: Stripe) -> FloatArray:
    """(H, W) coverage (0..1) of a painted stripe: a band of its width along its segment, edges a pixel soft."""
    width, height = size
    (u0, v0), (u1, v1) = stripe.start, stripe.end
    us, vs = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    du, dv = u1 - u0, v1 - v0
    t = np.clip(((us - u0) * du + (vs - v0) * dv) / max(du * du + dv * dv, 1e-9), 0.0, 1.0)
    distance = np.hypot(us - (u0 + t * du), vs - (v0 + t * dv))
    return np.clip(0.5 * stripe.width_px - distance + 0.5, 0.0, 1.0)


def _grain(size: tuple[int, int], seed: int) -> FloatArray:
    """(H, W) a fixed texture of unit standard deviation: noise smoothed over about two pixels (a floor's grain)."""
    width, height = size
    noise = np.random.default_rng(seed).standard_normal((height, width))
    smooth = cv2.GaussianBlur(noise, (0, 0), 1.0, borderType=cv2.BORDER_REFLECT)
    return np.asarray(smooth / max(float(smooth.std()), 1e-12))


def _floor(room: CameraRoom, size: tuple[int, int]) -> FloatArray:
    """(H, W) the wall or floor per ms before the mosaic: lit unevenly, with its grain, painted stripes and
    reflections (static structure, part of the background a detector must see past)."""
    width, height = size
    us, vs = np.meshgrid(np.arange(width), np.arange(height))
    x, y = us / (width - 1) - 0.5, vs / (height - 1) - 0.5
    wall = room.wall_level * (1 + room.wall_gradient[0] * x + room.wall_gradient[1] * y)
    wall *= 1.0 - room.vignetting * (x**2 + y**2) / 0.5
    if room.grain:
        wall = wall * np.maximum(1.0 + room.grain * _grain(size, room.grain_seed), 0.0)
    if room.stripes:
        paint = sum((stripe.level * _stripe(size, stripe) for stripe in room.stripes), np.zeros((height, width)))
        wall = wall + _blurred(paint, room.optics)
    for glow in room.reflections:
        (cu, cv), (su, sv) = glow.centre, glow.sigma_px
        wall = wall + glow.level * np.exp(-0.5 * (((us - cu) / su) ** 2 + ((vs - cv) / sv) ** 2))
    return np.asarray(wall, dtype=np.float64)


def _scene(room: CameraRoom, size: tuple[int, int]) -> _Scene:
    width, height = size
    wall = _response(room, (1.0, 1.0, 1.0), _floor(room, size), (0, 0))
    windows = np.zeros((height, width))
    light = np.zeros((height, width))
    for window in room.windows:
        sharp = window.level * _panes(size, window)
        blurred = _blurred(sharp, room.optics)
        windows += _response(room, window.colour, blurred, (0, 0))
        light += blurred * float(_LUMA @ np.asarray(window.colour))
    lamps = []
    for lamp in room.lamps:
        blurred = _blurred(lamp.level * _disc(size, lamp.centre, lamp.radius_px), room.optics)
        rows, cols = np.nonzero(blurred > 1e-3)
        v0, v1, u0, u1 = rows.min(), rows.max() + 1, cols.min(), cols.max() + 1
        patch = blurred[v0:v1, u0:u1]
        lamps.append((_response(room, lamp.colour, patch, (int(u0), int(v0))), int(u0), int(v0)))
        light += blurred * float(_LUMA @ np.asarray(lamp.colour))
    return _Scene(wall, windows, tuple(lamps), light)


class _NoiseBank:
    """Standard normal noise for many images: slices of a bank at a random row and column, with a random sign
    (cheap; two images share noise, even shifted by a pixel or two as a 3x3 sum of it would show, about once in
    a million pairs)."""

    def __init__(self, shape: tuple[int, int], rng: np.random.Generator) -> None:
        self.height, self.width = shape
        self.bank = rng.standard_normal((2 * shape[0], 2 * shape[1]), dtype=np.float32)

    def draw(self, rng: np.random.Generator) -> NDArray[np.float32]:
        row, col = int(rng.integers(0, self.height)), int(rng.integers(0, self.width))
        sign = np.float32(1.0 if rng.random() < 0.5 else -1.0)
        return self.bank[row : row + self.height, col : col + self.width] * sign


def _encoded(
    room: CameraRoom, signal: NDArray[np.float32], bank: _NoiseBank, rng: np.random.Generator
) -> tuple[NDArray[np.uint8] | NDArray[np.uint16] | bytes, str]:
    """The sensor's image of a signal (grey levels above black), as the camera sends it."""
    sensor = room.sensor
    sigma = np.sqrt(np.float32(sensor.read_noise**2) + np.float32(sensor.levels_per_electron) * np.maximum(signal, 0))
    raw = signal + sigma * bank.draw(rng) + np.float32(sensor.black_level)
    if sensor.encoding == "mono16":  # 12 bits, in the top of 16
        return (np.clip(np.round(raw * np.float32(4095 / 255)), 0, 4095).astype(np.uint16) * 16), "mono16"
    image = np.clip(np.round(raw), 0, 255).astype(np.uint8)
    encoding = sensor.encoding
    if sensor.encoding in _DEMOSAIC:
        image = cv2.cvtColor(image, _DEMOSAIC[sensor.encoding])
    elif sensor.colour and sensor.encoding != "bayer_rggb8":
        raise ValueError(f"the room renderer does not make {sensor.encoding} images")
    if sensor.jpeg_quality is None:
        return image, encoding
    return encode_compressed(image, encoding, sensor.jpeg_quality)


def render_camera(
    room: CameraRoom,
    size: tuple[int, int],
    led_paths: list[FloatArray],
    led_energy: list[FloatArray],
    rng: np.random.Generator,
    led_radius: list[FloatArray] | None = None,
) -> tuple[list[NDArray[np.uint8] | NDArray[np.uint16] | bytes], str, FloatArray, FloatArray]:
    """One camera's images.

    Args:
        room: the room and the sensor.
        size: (width, height).
        led_paths: per image (K, M, 2) each LED's positions over the exposure (NaN: not in view).
        led_energy: per image (K, M) each LED's light per step (grey levels x px, this exposure).
        rng: noise and flicker.
        led_radius: per image (K,) each LED's glowing disc's radius, px (None: points).

    Returns:
        The images (arrays, or bytes when compressed), their encoding (or CompressedImage format), and
        per image and LED (N, K) its brightest pixel before clipping and the static picture behind it
        (grey levels), for the truth.
    """
    scene = _scene(room, size)
    exposure = room.sensor.exposure_ms
    static = ((scene.wall + scene.windows) * exposure).astype(np.float32)
    bank = _NoiseBank((size[1], size[0]), rng)
    images: list[NDArray[np.uint8] | NDArray[np.uint16] | bytes] = []
    encoding = room.sensor.encoding
    k = led_paths[0].shape[0] if led_paths else 0
    peaks = np.zeros((len(led_paths), k))
    luma = float(_LUMA @ np.asarray(room.led_colour))
    headroom = 255.0 - room.sensor.black_level
    for i, (paths, energy) in enumerate(zip(led_paths, led_energy, strict=True)):
        signal = static.copy()
        for lamp, (patch, u0, v0) in zip(room.lamps, scene.lamps, strict=True):
            gain = exposure * (1.0 + lamp.flicker * rng.uniform(-1.0, 1.0))
            signal[v0 : v0 + patch.shape[0], u0 : u0 + patch.shape[1]] += (gain * patch).astype(np.float32)
        for p in range(k):
            keep = np.all(np.isfinite(paths[p]), axis=1)
            if not keep.any():
                continue
            radius = 0.0 if led_radius is None else float(np.nan_to_num(led_radius[i][p]))
            patch, u0, v0 = _spread(paths[p][keep], energy[p][keep], room.optics, size, radius)
            if patch.size == 0:
                continue
            peaks[i, p] = float(patch.max()) * luma
            if room.saturated_shift_px and _saturates(patch * luma, static[v0:, u0:], headroom):
                moved = _outward(paths[p][keep], room.optical_centre or _centre(size), room.saturated_shift_px)
                patch, u0, v0 = _spread(moved, energy[p][keep], room.optics, size, radius)
            recorded = _response(room, room.led_colour, patch, (u0, v0))
            signal[v0 : v0 + patch.shape[0], u0 : u0 + patch.shape[1]] += recorded.astype(np.float32)
        image, encoding = _encoded(room, signal, bank, rng)
        images.append(image)
    return images, encoding, peaks, scene.luma_light * exposure


def _saturates(patch: FloatArray, static: NDArray[np.float32], headroom: float) -> bool:
    """Whether a light's patch over the static picture (from the patch's top-left pixel on) clips anywhere."""
    behind = static[: patch.shape[0], : patch.shape[1]]
    return bool(np.any(patch[: behind.shape[0], : behind.shape[1]] + behind >= headroom))


def _centre(size: tuple[int, int]) -> tuple[float, float]:
    """The centre of an image of ``size`` (width, height), px."""
    return (size[0] - 1) / 2.0, (size[1] - 1) / 2.0


def _outward(path: FloatArray, centre: tuple[float, float], shift_px: float) -> FloatArray:
    """(M, 2) a light's path moved ``shift_px`` away from ``centre`` (along the line from it)."""
    away = path.mean(axis=0) - np.asarray(centre)
    return np.asarray(path + shift_px * away / max(float(np.linalg.norm(away)), 1e-9))


def scene_level(room: CameraRoom, size: tuple[int, int]) -> FloatArray:
    """(H, W) the static picture's luma (grey levels above black) at this exposure, lamps at their mean."""
    scene = _scene(replace(room, sensor=replace(room.sensor, encoding="mono8", jpeg_quality=None)), size)
    level = scene.wall + scene.windows
    for patch, u0, v0 in scene.lamps:
        level[v0 : v0 + patch.shape[0], u0 : u0 + patch.shape[1]] += patch
    return level * room.sensor.exposure_ms
