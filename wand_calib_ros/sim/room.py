"""Camera images of a waved wand in a real room: what a first take in a lab looks like.

Everything is in grey levels of an 8-bit image, per millisecond of exposure where it is light:

- **LEDs.** The light an LED sends a camera falls as 1/d^2 with its distance and, as diffused LEDs on
  a wand glow around it, as sin(a)^p with the angle a between the wand and the line of sight (dim
  when the wand points at the camera). Over the exposure the LED moves: its light is spread along
  its path (a motion streak, centred on the mid-exposure position, which is the image's stamp).
- **Optics.** Every light goes through the same point spread: a Gaussian core, a bloom (a few pixels)
  and a wide glare, so bright LEDs and lamps have halos, and the sensor clips them to flat tops.
- **The room.** A wall lit unevenly (a gradient and vignetting); windows, bright panes split by bars;
  ceiling lamps, small discs far brighter than the sensor's full scale whose brightness flickers from
  image to image.
- **The sensor.** Shot noise (variance proportional to the signal) and read noise, a black level,
  clipping at full scale and quantisation; mono8, mono16 (12 bits in 16), a Bayer mosaic, colour
  demosaiced from it, and JPEG compression of mono or colour images.

The truth of each image is each LED's projection at mid-exposure with how much it stands out
(:class:`CameraTruth`); :func:`clearly_visible` says which views a detector must find.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.special import erf

from wand_calib_ros.core.model.camera_model import project
from wand_calib_ros.core.model.rig import WandObservations
from wand_calib_ros.io.images import encode_compressed
from wand_calib_ros.sim.clocks import CameraClock, film, stamp_ns, synchronised_clocks
from wand_calib_ros.sim.motion import WavedWand, shared_volume, waved_wand
from wand_calib_ros.sim.scenarios import Scenario, visibility

FloatArray = NDArray[np.float64]

#: A view is clearly visible when every LED stands out by at least this much (grey levels) ...
MIN_CONTRAST = 10.0
#: ... and by this many noise standard deviations of its background, ...
MIN_CONTRAST_SIGMAS = 5.0
#: ... lies this far inside the image (px) ...
MIN_BORDER_PX = 6.0
#: ... this far from the other LEDs (px) ...
MIN_SEPARATION_PX = 15.0
#: ... and this far (px) beyond a lamp's disc or a window's frame.
LAMP_MARGIN_PX = 8.0
#: The exposure at which a room's light levels are quoted, ms.
REFERENCE_EXPOSURE_MS = 6.0
#: Colour encodings rendered through a Bayer mosaic (RGGB) and OpenCV's demosaicing.
_DEMOSAIC = {"bgr8": cv2.COLOR_BayerRGGB2BGR, "rgb8": cv2.COLOR_BayerRGGB2RGB}
#: Rec. 601 luma of an RGB colour (what a grey conversion of a colour image sees).
_LUMA = np.array([0.299, 0.587, 0.114])


@dataclass(frozen=True)
class Optics:
    """The point spread of the lens: fractions of the light in a core, a bloom and a glare.

    Attributes:
        core_sigma_px: standard deviation of the sharp core, px.
        bloom: (fraction of the light, standard deviation px) of the bloom around bright spots.
        glare: (fraction, standard deviation px) of the wide glare.
    """

    core_sigma_px: float = 1.0
    bloom: tuple[float, float] = (0.08, 3.0)
    glare: tuple[float, float] = (0.02, 10.0)

    def terms(self) -> tuple[tuple[float, float], ...]:
        """(fraction, sigma px) of each Gaussian term."""
        core = 1.0 - self.bloom[0] - self.glare[0]
        return ((core, self.core_sigma_px), self.bloom, self.glare)


@dataclass(frozen=True)
class Sensor:
    """Exposure, noise and what the camera sends.

    Attributes:
        exposure_ms: exposure time, ms.
        read_noise: standard deviation of the read noise, grey levels.
        levels_per_electron: grey levels one photo-electron makes (shot noise variance = signal x this).
        black_level: grey level of no light.
        encoding: sensor_msgs/Image encoding: mono8, mono16, bayer_rggb8, bgr8 or rgb8.
        jpeg_quality: sent JPEG-compressed at this quality (None: raw).
    """

    exposure_ms: float = REFERENCE_EXPOSURE_MS
    read_noise: float = 1.2
    levels_per_electron: float = 0.25
    black_level: float = 2.0
    encoding: str = "mono8"
    jpeg_quality: int | None = None

    @property
    def colour(self) -> bool:
        return self.encoding not in ("mono8", "mono16")

    def noise(self, signal: FloatArray) -> FloatArray:
        """Standard deviation (grey levels) of an image's noise at a given signal above black."""
        return np.sqrt(self.read_noise**2 + self.levels_per_electron * np.maximum(signal, 0.0))


@dataclass(frozen=True)
class Lamp:
    """A ceiling lamp: a disc far brighter than full scale.

    Attributes:
        centre: (u, v) px.
        radius_px: radius of the disc.
        level: brightness of the disc before the optics, grey levels per ms.
        colour: relative (R, G, B) response.
        flicker: brightness varies from image to image uniformly within +- this fraction.
    """

    centre: tuple[float, float]
    radius_px: float
    level: float
    colour: tuple[float, float, float] = (1.0, 0.85, 0.6)
    flicker: float = 0.1


@dataclass(frozen=True)
class Window:
    """A window: bright panes split by bars.

    Attributes:
        box: (u0, v0, u1, v1) px.
        level: brightness of the panes before the optics, grey levels per ms.
        panes: (columns, rows).
        bar_px: width of the bars.
        colour: relative (R, G, B) response.
    """

    box: tuple[float, float, float, float]
    level: float
    panes: tuple[int, int] = (2, 2)
    bar_px: float = 5.0
    colour: tuple[float, float, float] = (0.85, 0.95, 1.0)


@dataclass(frozen=True)
class CameraRoom:
    """What one camera sees besides the wand, and how it sees it.

    Attributes:
        sensor: exposure, noise and encoding.
        optics: the lens's point spread.
        lamps: lamps in view.
        windows: windows in view.
        wall_level: the wall's brightness at the image centre, grey levels per ms.
        wall_gradient: (along u, along v) relative change of the wall's brightness across the image.
        vignetting: relative fall of the wall's brightness at the image corners.
        led_peak: peak (grey levels per ms, before clipping) of a still LED seen on its axis from
            ``led_distance_mm``.
        led_distance_mm: the distance ``led_peak`` is quoted at.
        led_falloff: the exponent p of the LEDs' fall-off as the wand turns towards the line of sight.
        led_colour: relative (R, G, B) response to the LEDs.
    """

    sensor: Sensor = field(default_factory=Sensor)
    optics: Optics = field(default_factory=Optics)
    lamps: tuple[Lamp, ...] = ()
    windows: tuple[Window, ...] = ()
    wall_level: float = 1.5
    wall_gradient: tuple[float, float] = (0.4, -0.3)
    vignetting: float = 0.35
    led_peak: float = 300.0
    led_distance_mm: float = 1000.0
    led_falloff: float = 3.0
    led_colour: tuple[float, float, float] = (1.0, 1.0, 1.0)


@dataclass(frozen=True, eq=False)
class CameraTruth:
    """What was drawn in one camera's images.

    Attributes:
        name: the camera.
        stamps_ns: (N,) the images' stamps (mid-exposure).
        uv: (N, K, 2) each LED's projection at mid-exposure (NaN: outside the image or behind the camera).
        contrast: (N, K) how far the LED's brightest pixel stands above what is behind it, grey levels
            (clipping at full scale included, noise not).
        noise: (N, K) the noise standard deviation of what is behind the LED, grey levels.
        light: (N, K) the lamps' and windows' light behind the LED, grey levels.
        near_lamp: (N, K) the LED is within LAMP_MARGIN_PX of a lamp's disc or a window.
        streak_px: (N, K) the length of the LED's motion streak, px.
        image_size: (width, height).
    """

    name: str
    stamps_ns: NDArray[np.int64]
    uv: FloatArray
    contrast: FloatArray
    noise: FloatArray
    light: FloatArray
    near_lamp: NDArray[np.bool_]
    streak_px: FloatArray
    image_size: tuple[int, int]


@dataclass(frozen=True, eq=False)
class RoomRecording:
    """A rendered take.

    Attributes:
        frames: (camera, stamp ns, payload, encoding) in stamp order: the payload is the image array
            for raw encodings, the compressed bytes for JPEG (``encoding`` then the CompressedImage
            format, e.g. "bgr8; jpeg compressed bgr8").
        truth: per camera what was drawn.
        rooms: per camera the room it saw.
    """

    frames: list[tuple[str, int, NDArray[np.uint8] | NDArray[np.uint16] | bytes, str]]
    truth: tuple[CameraTruth, ...]
    rooms: tuple[CameraRoom, ...]

    def clearly_visible(self) -> list[NDArray[np.bool_]]:
        """Per camera the (N,) images whose wand a detector must find (:func:`clearly_visible`)."""
        return [clearly_visible(t) for t in self.truth]


def clearly_visible(truth: CameraTruth) -> NDArray[np.bool_]:
    """(N,) the images in which every LED is clearly visible: on the image at least MIN_BORDER_PX inside its
    border, standing out by MIN_CONTRAST grey levels and MIN_CONTRAST_SIGMAS of its background's noise, not on a
    lamp or a window (their light behind it less than half its contrast, and LAMP_MARGIN_PX beyond them),
    and MIN_SEPARATION_PX from the others."""
    width, height = truth.image_size
    uv = truth.uv
    with np.errstate(invalid="ignore"):
        inside = (
            (uv[..., 0] >= MIN_BORDER_PX)
            & (uv[..., 0] <= width - 1 - MIN_BORDER_PX)
            & (uv[..., 1] >= MIN_BORDER_PX)
            & (uv[..., 1] <= height - 1 - MIN_BORDER_PX)
        )
        bright = truth.contrast >= np.maximum(MIN_CONTRAST, MIN_CONTRAST_SIGMAS * truth.noise)
        clear = (truth.light < 0.5 * truth.contrast) & ~truth.near_lamp
        gaps = np.linalg.norm(uv[:, :, None] - uv[:, None, :], axis=-1)
    k = uv.shape[1]
    apart = np.all(gaps[:, ~np.eye(k, dtype=bool)] >= MIN_SEPARATION_PX, axis=1)
    return np.all(inside & bright & clear, axis=1) & apart


# --- the picture -------------------------------------------------------------------------------------------


def _pixel_gaussian(centres: FloatArray, start: int, size: int, sigma: float) -> FloatArray:
    """(M, size) the share of a unit 1D Gaussian at each of M ``centres`` that falls in pixels start..start+size-1."""
    edges = np.arange(start, start + size + 1) - 0.5
    cdf = 0.5 * (1.0 + erf((edges[None, :] - centres[:, None]) / (np.sqrt(2.0) * sigma)))
    return np.diff(cdf, axis=1)


def _spread(path: FloatArray, energy: FloatArray, optics: Optics, size: tuple[int, int]) -> tuple[FloatArray, int, int]:
    """A light moving along ``path`` through the optics, as a patch of the image.

    Args:
        path: (M, 2) its positions over the exposure (equal time steps), px.
        energy: (M,) the light of each step (grey levels x px).
        optics: the point spread.
        size: the image's (width, height).

    Returns:
        The (h, w) patch and its top-left pixel (u0, v0).
    """
    reach = 4.0 * max(sigma for _, sigma in optics.terms())
    u0 = max(int(np.floor(path[:, 0].min() - reach)), 0)
    v0 = max(int(np.floor(path[:, 1].min() - reach)), 0)
    u1 = min(int(np.ceil(path[:, 0].max() + reach)), size[0] - 1)
    v1 = min(int(np.ceil(path[:, 1].max() + reach)), size[1] - 1)
    if u1 < u0 or v1 < v0:
        return np.zeros((0, 0)), 0, 0
    patch = np.zeros((v1 - v0 + 1, u1 - u0 + 1))
    for fraction, sigma in optics.terms():
        gx = _pixel_gaussian(path[:, 0], u0, u1 - u0 + 1, sigma)
        gy = _pixel_gaussian(path[:, 1], v0, v1 - v0 + 1, sigma)
        patch += fraction * (gy * energy[:, None]).T @ gx
    return patch, u0, v0


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


def _scene(room: CameraRoom, size: tuple[int, int]) -> _Scene:
    width, height = size
    us, vs = np.meshgrid(np.arange(width), np.arange(height))
    x, y = us / (width - 1) - 0.5, vs / (height - 1) - 0.5
    wall = room.wall_level * (1 + room.wall_gradient[0] * x + room.wall_gradient[1] * y)
    wall *= 1.0 - room.vignetting * (x**2 + y**2) / 0.5
    wall = _response(room, (1.0, 1.0, 1.0), wall, (0, 0))
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
    """Standard normal noise for many images: slices of a bank at random rows, with a random sign (cheap, and
    no image's noise is another's)."""

    def __init__(self, shape: tuple[int, int], rng: np.random.Generator) -> None:
        self.height = shape[0]
        self.bank = rng.standard_normal((2 * shape[0], shape[1]), dtype=np.float32)

    def draw(self, rng: np.random.Generator) -> NDArray[np.float32]:
        row = int(rng.integers(0, self.height))
        sign = np.float32(1.0 if rng.random() < 0.5 else -1.0)
        return self.bank[row : row + self.height] * sign


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
) -> tuple[list[NDArray[np.uint8] | NDArray[np.uint16] | bytes], str, FloatArray, FloatArray]:
    """One camera's images.

    Args:
        room: the room and the sensor.
        size: (width, height).
        led_paths: per image (K, M, 2) each LED's positions over the exposure (NaN: not in view).
        led_energy: per image (K, M) each LED's light per step (grey levels x px, this exposure).
        rng: noise and flicker.

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
    for i, (paths, energy) in enumerate(zip(led_paths, led_energy, strict=True)):
        signal = static.copy()
        for lamp, (patch, u0, v0) in zip(room.lamps, scene.lamps, strict=True):
            gain = exposure * (1.0 + lamp.flicker * rng.uniform(-1.0, 1.0))
            signal[v0 : v0 + patch.shape[0], u0 : u0 + patch.shape[1]] += (gain * patch).astype(np.float32)
        for p in range(k):
            keep = np.all(np.isfinite(paths[p]), axis=1)
            if not keep.any():
                continue
            patch, u0, v0 = _spread(paths[p][keep], energy[p][keep], room.optics, size)
            if patch.size == 0:
                continue
            peaks[i, p] = float(patch.max()) * float(_LUMA @ np.asarray(room.led_colour))
            recorded = _response(room, room.led_colour, patch, (u0, v0))
            signal[v0 : v0 + patch.shape[0], u0 : u0 + patch.shape[1]] += recorded.astype(np.float32)
        image, encoding = _encoded(room, signal, bank, rng)
        images.append(image)
    return images, encoding, peaks, scene.luma_light * exposure


# --- a take -----------------------------------------------------------------------------------------------


def _falloff(to_camera: FloatArray, direction: FloatArray, power: float) -> FloatArray:
    """sin(a)^p of the angle a between the wand's direction and the line of sight (a floor of 1e-3)."""
    cosine = np.einsum("...i,...i->...", to_camera, direction) / np.linalg.norm(to_camera, axis=-1)
    return np.maximum(np.sqrt(np.clip(1.0 - cosine**2, 0.0, 1.0)), 1e-3) ** power


def _exposure_steps(streak_px: float) -> int:
    """Steps along a motion streak: about two per pixel of its length (smooth under a 1 px core)."""
    return int(np.clip(np.ceil(2.0 * streak_px) + 1, 3, 200))


def _led_light(
    scenario: Scenario, camera: int, room: CameraRoom, trajectory: WavedWand, times: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """(M, K, 2) pixels and (M, K) light (grey levels x px per ms) of the LEDs at ``times`` (NaN: not seen)."""
    true_camera = scenario.cameras[camera]
    motion = trajectory.at(times)
    points = motion.points(scenario.wand)  # (M, K, 3)
    in_camera = true_camera.pose.apply(points)
    uv = project(true_camera.model, in_camera)
    seen = visibility(scenario, motion.wand_a, motion.direction, motion.facing)[:, camera]
    distance = np.linalg.norm(in_camera, axis=-1)
    to_camera = true_camera.pose.center[None, None, :] - points
    falloff = _falloff(to_camera, motion.direction[:, None, :], room.led_falloff)
    core = room.optics.terms()[0][0]
    energy = room.led_peak / core * 2 * np.pi * room.optics.core_sigma_px**2
    light = energy * (room.led_distance_mm / distance) ** 2 * falloff
    return np.where(seen[..., None], uv, np.nan), np.where(seen, light, np.nan)


def render_room_take(
    scenario: Scenario,
    rooms: tuple[CameraRoom, ...],
    trajectory: WavedWand,
    clocks: tuple[CameraClock, ...],
    duration_s: float,
    rng: np.random.Generator,
) -> RoomRecording:
    """Every camera's images of a wand waved in a room (global shutters; each image stamped at mid-exposure).

    Args:
        scenario: the rig and its true cameras.
        rooms: per camera its room and sensor.
        trajectory: the wand's motion.
        clocks: per camera when it exposes.
        duration_s: length of the take.
        rng: the only source of randomness.
    """
    takes = film(scenario, trajectory, clocks, duration_s, rng)
    frames: list[tuple[int, int, str, NDArray[np.uint8] | NDArray[np.uint16] | bytes, str]] = []
    truths = []
    for c, (camera, room, take) in enumerate(zip(scenario.cameras, rooms, takes, strict=True)):
        size = camera.spec.image_size
        exposure_s = room.sensor.exposure_ms / 1000.0
        mids = take.exposures
        # the streak's length from its ends, then the steps along it
        ends, _ = _led_light(
            scenario, c, room, trajectory, np.concatenate([mids - exposure_s / 2, mids + exposure_s / 2])
        )
        streak = np.linalg.norm(ends[: len(mids)] - ends[len(mids) :], axis=-1)  # (N, K)
        paths, energies = [], []
        for i, mid in enumerate(mids):
            longest = float(np.nanmax(streak[i])) if np.isfinite(streak[i]).any() else 0.0
            steps = _exposure_steps(longest)
            times = mid + exposure_s * (np.arange(steps) / (steps - 1) - 0.5)
            uv, light = _led_light(scenario, c, room, trajectory, times)
            paths.append(np.transpose(uv, (1, 0, 2)))
            energies.append(light.T * room.sensor.exposure_ms / steps)
        images, encoding, peaks, light = render_camera(room, size, paths, energies, rng)
        uv_mid = take.uv
        behind = _sample(light, uv_mid)
        static_level = _sample(_scene_level(room, size), uv_mid)
        headroom = 255.0 - room.sensor.black_level - static_level
        contrast = np.where(np.isfinite(uv_mid[..., 0]), np.minimum(peaks, np.maximum(headroom, 0.0)), 0.0)
        near_lamp = np.zeros(uv_mid.shape[:2], dtype=bool)
        for lamp in room.lamps:
            with np.errstate(invalid="ignore"):
                near_lamp |= np.linalg.norm(uv_mid - np.array(lamp.centre), axis=-1) <= lamp.radius_px + LAMP_MARGIN_PX
        for window in room.windows:
            u0, v0, u1, v1 = window.box
            with np.errstate(invalid="ignore"):
                near_lamp |= (
                    (uv_mid[..., 0] >= u0 - LAMP_MARGIN_PX)
                    & (uv_mid[..., 0] <= u1 + LAMP_MARGIN_PX)
                    & (uv_mid[..., 1] >= v0 - LAMP_MARGIN_PX)
                    & (uv_mid[..., 1] <= v1 + LAMP_MARGIN_PX)
                )
        truths.append(
            CameraTruth(
                camera.spec.name,
                stamp_ns(take.stamps),
                uv_mid,
                contrast,
                room.sensor.noise(static_level),
                behind,
                near_lamp,
                np.nan_to_num(streak),
                size,
            )
        )
        for stamp, image in zip(stamp_ns(take.stamps), images, strict=True):
            frames.append((int(stamp), c, camera.spec.name, image, encoding))
    frames.sort(key=lambda f: (f[0], f[1]))
    return RoomRecording([(name, stamp, image, enc) for stamp, _, name, image, enc in frames], tuple(truths), rooms)


def _scene_level(room: CameraRoom, size: tuple[int, int]) -> FloatArray:
    """(H, W) the static picture's luma (grey levels above black) at this exposure, lamps at their mean."""
    scene = _scene(replace(room, sensor=replace(room.sensor, encoding="mono8", jpeg_quality=None)), size)
    level = scene.wall + scene.windows
    for patch, u0, v0 in scene.lamps:
        level[v0 : v0 + patch.shape[0], u0 : u0 + patch.shape[1]] += patch
    return level * room.sensor.exposure_ms


def _sample(image: FloatArray, uv: FloatArray) -> FloatArray:
    """``image`` at the nearest pixel of each (..., 2) point (0 where not finite)."""
    height, width = image.shape
    finite = np.all(np.isfinite(uv), axis=-1)
    u = np.clip(np.round(np.where(finite, uv[..., 0], 0)).astype(int), 0, width - 1)
    v = np.clip(np.round(np.where(finite, uv[..., 1], 0)).astype(int), 0, height - 1)
    return np.where(finite, image[v, u], 0.0)


# --- rooms ------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RoomOptions:
    """A room for every camera of a rig.

    Attributes:
        sensor: every camera's sensor (exposure, encoding, JPEG).
        lamps: lamps in each camera's view.
        windows: cameras that see a window: "one" (the first camera), "every" or "none".
        lamp_near_path: one lamp of each camera 12-18 px beside the wand's path.
        lamp_row: three of each camera's lamps in a row, spaced as the wand's LEDs (a static false wand).
        led_peak: peak (grey levels, still, on axis, before clipping) of an LED at the camera's median
            distance of the wand, at REFERENCE_EXPOSURE_MS.
        led_falloff: exponent of the LEDs' fall-off as the wand turns towards the line of sight.
        led_colour: (R, G, B) of the LEDs.
    """

    sensor: Sensor = field(default_factory=Sensor)
    lamps: int = 2
    windows: str = "one"
    lamp_near_path: bool = False
    lamp_row: bool = False
    led_peak: float = 400.0
    led_falloff: float = 3.0
    led_colour: tuple[float, float, float] = (1.0, 1.0, 1.0)


def _lamp_positions(
    size: tuple[int, int], count: int, avoid: list[tuple[float, float, float, float]], rng: np.random.Generator
) -> list[tuple[float, float]]:
    """Random lamp centres at least 60 px apart, 20 px inside the image and outside the windows."""
    width, height = size
    placed: list[tuple[float, float]] = []
    for _ in range(1000):
        if len(placed) == count:
            break
        u, v = rng.uniform(20, width - 20), rng.uniform(20, height - 20)
        if any(a - 20 <= u <= c + 20 and b - 20 <= v <= d + 20 for a, b, c, d in avoid):
            continue
        if all(np.hypot(u - pu, v - pv) >= 60 for pu, pv in placed):
            placed.append((u, v))
    return placed


def _beside_path(uv: FloatArray, size: tuple[int, int], rng: np.random.Generator) -> tuple[float, float] | None:
    """A point 12-18 px beside the path of one LED (sideways to its motion) and no nearer to any LED position of
    the take, 30 px inside the image; None when the path gives no such point."""
    points = uv.reshape(-1, 2)
    points = points[np.all(np.isfinite(points), axis=1)]
    width, height = size
    track = uv[:, 1]  # B
    for _ in range(200):
        i = int(rng.integers(1, len(track)))
        if not (np.all(np.isfinite(track[i])) and np.all(np.isfinite(track[i - 1]))):
            continue
        motion = track[i] - track[i - 1]
        if np.linalg.norm(motion) < 1.0:
            continue
        side = np.array([-motion[1], motion[0]]) / np.linalg.norm(motion)
        candidate = track[i] + rng.uniform(12.0, 18.0) * side * rng.choice([-1.0, 1.0])
        if not (30 <= candidate[0] <= width - 30 and 30 <= candidate[1] <= height - 30):
            continue
        if np.min(np.linalg.norm(points - candidate, axis=1)) >= 11.0:
            return float(candidate[0]), float(candidate[1])
    return None


def room_for(
    scenario: Scenario,
    take_uv: list[FloatArray],
    distances_mm: list[float],
    options: RoomOptions,
    rng: np.random.Generator,
) -> tuple[CameraRoom, ...]:
    """Rooms for a rig's cameras: lamps, windows and LED brightness as ``options`` say.

    Args:
        scenario: the rig.
        take_uv: per camera the (N, K, 2) pixels of the LEDs over the take (for lamps beside its path).
        distances_mm: per camera the LEDs' median distance over the take (``options.led_peak`` is quoted there).
        options: what the room holds.
        rng: where things go.
    """
    rooms = []
    for c, (camera, uv) in enumerate(zip(scenario.cameras, take_uv, strict=True)):
        size = camera.spec.image_size
        width, height = size
        windows: list[Window] = []
        if options.windows == "every" or (options.windows == "one" and c == 0):
            w, h = rng.uniform(0.2, 0.32) * width, rng.uniform(0.2, 0.3) * height
            u0 = rng.choice([rng.uniform(5, 0.2 * width), rng.uniform(0.6 * width, width - w - 5)])
            v0 = rng.uniform(5, 0.15 * height)
            level = rng.uniform(150.0, 220.0) / REFERENCE_EXPOSURE_MS
            windows.append(Window((u0, v0, u0 + w, v0 + h), level))
        boxes = [w.box for w in windows]
        lamps: list[Lamp] = []
        count = options.lamps
        if options.lamp_near_path and count > 0:
            near = _beside_path(uv, size, rng)
            if near is not None:
                lamps.append(Lamp(near, rng.uniform(2.0, 3.5), rng.uniform(300.0, 900.0)))
                count -= 1
        if options.lamp_row and count >= 3:
            start = np.array([rng.uniform(80, width - 80), rng.uniform(60, height / 2)])
            direction = rng.normal(size=2)
            direction /= np.linalg.norm(direction)
            spacing = rng.uniform(25.0, 45.0)
            for t in (0.0, 2.0, 3.0):  # the wand's |AB| / |BC| = 2
                u, v = np.clip(start + t * spacing * direction, 10, [width - 10, height - 10])
                lamps.append(Lamp((float(u), float(v)), rng.uniform(2.0, 4.0), rng.uniform(300.0, 1500.0)))
            count -= 3
        taken = [lamp.centre for lamp in lamps]
        for centre in _lamp_positions(size, count + len(taken), boxes, rng):
            if len(lamps) >= options.lamps:
                break
            if all(np.hypot(centre[0] - u, centre[1] - v) >= 60 for u, v in taken):
                lamps.append(Lamp(centre, rng.uniform(2.0, 5.0), rng.uniform(300.0, 2000.0)))
        rooms.append(
            CameraRoom(
                sensor=options.sensor,
                lamps=tuple(lamps),
                windows=tuple(windows),
                wall_gradient=(float(rng.uniform(-0.5, 0.5)), float(rng.uniform(-0.5, 0.5))),
                led_peak=options.led_peak / REFERENCE_EXPOSURE_MS,
                led_distance_mm=distances_mm[c],
                led_falloff=options.led_falloff,
                led_colour=options.led_colour,
            )
        )
    return tuple(rooms)


#: Named rooms of the benchmark and the tests.
ROOM_SCENES: dict[str, Callable[[], RoomOptions]] = {
    "lamps_window": lambda: RoomOptions(Sensor(exposure_ms=6.0)),
    "colour_jpeg": lambda: RoomOptions(Sensor(exposure_ms=12.0, encoding="bgr8", jpeg_quality=85), lamps=3),
    "lamp_near_path": lambda: RoomOptions(Sensor(exposure_ms=6.0), lamps=2, lamp_near_path=True),
    "lamp_row": lambda: RoomOptions(Sensor(exposure_ms=6.0), lamps=4, lamp_row=True),
    "short_exposure": lambda: RoomOptions(Sensor(exposure_ms=4.0)),
    "long_exposure": lambda: RoomOptions(Sensor(exposure_ms=16.0)),
    "window_everywhere": lambda: RoomOptions(Sensor(exposure_ms=6.0), windows="every"),
    "mono16": lambda: RoomOptions(Sensor(exposure_ms=6.0, encoding="mono16")),
    "bayer": lambda: RoomOptions(Sensor(exposure_ms=6.0, encoding="bayer_rggb8")),
    "hard": lambda: RoomOptions(Sensor(exposure_ms=16.0), lamps=4, windows="every", lamp_near_path=True, lamp_row=True),
}


def room_take(
    scenario: Scenario,
    options: RoomOptions,
    duration_s: float,
    rng: np.random.Generator,
    *,
    fps: float = 30.0,
    speed_mm_s: float = 1000.0,
    clocks: tuple[CameraClock, ...] | None = None,
) -> RoomRecording:
    """A wand waved for ``duration_s`` through the part of the scenario's volume its cameras share, in rooms
    made by ``options`` (hardware-triggered cameras unless ``clocks`` are given)."""
    trajectory = waved_wand(shared_volume(scenario, rng), scenario.wand, rng, speed_mm_s=speed_mm_s)
    clocks = clocks if clocks is not None else synchronised_clocks(len(scenario.cameras), fps=fps)
    outline = film(scenario, trajectory, clocks, duration_s, rng)
    distances = []
    for camera, take in zip(scenario.cameras, outline, strict=True):
        points = trajectory.at(take.exposures).points(scenario.wand)
        near = np.linalg.norm(camera.pose.apply(points), axis=-1)[np.isfinite(take.uv[..., 0])]
        distances.append(float(np.median(near)) if near.size else float(np.linalg.norm(camera.pose.center)) + 1000.0)
    rooms = room_for(scenario, [t.uv for t in outline], distances, options, rng)
    return render_room_take(scenario, rooms, trajectory, clocks, duration_s, rng)


def drawn_observations(recording: RoomRecording, names: tuple[str, ...]) -> WandObservations:
    """The truth as observations: each image's mid-exposure LED pixels where every LED is clearly visible,
    grouped into frames as the detector groups its views (same stamps)."""
    from wand_calib_ros.collection.sync import frames_to_observations, group_by_stamps

    detections = []
    for truth, visible in zip(recording.truth, recording.clearly_visible(), strict=True):
        for stamp, uv, ok in zip(truth.stamps_ns, truth.uv, visible, strict=True):
            detections.append((truth.name, int(stamp), uv if ok else None))
    k = recording.truth[0].uv.shape[1]
    return frames_to_observations(group_by_stamps(names, detections, n_points=k), names, k)
