"""Rooms for the renderer: where each camera's lamps and windows go and how bright the wand's LEDs are, and the
named scenes of the benchmark and the tests."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.sim.room import REFERENCE_EXPOSURE_MS, CameraRoom, Lamp, Sensor, Window
from wand_calib_ros.sim.scenarios import Scenario

FloatArray = NDArray[np.float64]


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
