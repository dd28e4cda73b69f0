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

The renderer is four modules: the records of a room and of what was drawn (here, with
:func:`clearly_visible`, which says which views a detector must find), the picture
(:mod:`~wand_calib_ros.sim.room_images`), the take (:mod:`~wand_calib_ros.sim.room_take`: the wand's
LEDs through each camera over time) and the rooms' layouts (:mod:`~wand_calib_ros.sim.room_layout`).
The truth of each image is each LED's projection at mid-exposure with how much it stands out
(:class:`CameraTruth`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

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
class Stripe:
    """A painted line on a floor (a track, a marking): a straight band brighter than the floor.

    Attributes:
        start: (u, v) one end, px.
        end: (u, v) the other end, px.
        width_px: its width.
        level: how much brighter than the floor it is, before the optics, grey levels per ms.
    """

    start: tuple[float, float]
    end: tuple[float, float]
    width_px: float
    level: float


@dataclass(frozen=True)
class Reflection:
    """A broad specular reflection of a ceiling lamp on a glossy floor: a soft elliptical glow.

    Attributes:
        centre: (u, v) px.
        sigma_px: (along u, along v) its Gaussian widths, px.
        level: its peak above the floor, grey levels per ms.
    """

    centre: tuple[float, float]
    sigma_px: tuple[float, float]
    level: float


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
        led_diameter_mm: the diameter of each LED's glowing diffuser (0: a point; near a wide-angle camera a
            12 mm ball is a disc of several px).
        stripes: painted lines on the floor or wall (static structure brighter than it).
        reflections: broad reflections of lamps on a glossy floor.
        grain: a fixed texture of the wall or floor: its relative standard deviation (0: a smooth wall).
        grain_seed: the seed of that texture (it is the same in every image).
        saturated_shift_px: LED spots that saturate are drawn this far (px) radially outward from the lens's axis
            (``optical_centre``), a bias on purpose (a lens's coma): the truth stays where the LED is.
        optical_centre: where the lens's axis meets the image (its principal point), px; None: the image centre.
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
    led_diameter_mm: float = 0.0
    stripes: tuple[Stripe, ...] = ()
    reflections: tuple[Reflection, ...] = ()
    grain: float = 0.0
    grain_seed: int = 0
    saturated_shift_px: float = 0.0
    optical_centre: tuple[float, float] | None = None


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
        peak: (N, K) the LED's brightest pixel before clipping, grey levels (0 where not drawn).
        full_scale: the grey levels a pixel holds above black (what ``peak`` saturates at).
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
    peak: FloatArray | None = None
    full_scale: float = 253.0

    def over_saturation(self) -> FloatArray:
        """(N,) each image's brightest LED before clipping, in multiples of full scale (0 where none was drawn)."""
        if self.peak is None:
            return np.zeros(self.uv.shape[0])
        return np.asarray(np.nanmax(np.where(np.isfinite(self.uv[..., 0]), self.peak, 0.0), axis=1) / self.full_scale)


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
