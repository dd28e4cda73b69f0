"""Rooms for the renderer: where each camera's lamps and windows go and how bright the wand's LEDs are, and the
named scenes of the benchmark and the tests."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.sim.room import REFERENCE_EXPOSURE_MS, CameraRoom, Lamp, Optics, Reflection, Sensor, Stripe, Window
from wand_calib_ros.sim.scenarios import SCENARIOS, Scenario

FloatArray = NDArray[np.float64]


#: What lies behind the wand: "wall" a smooth wall lit unevenly; "painted" a lab floor with a painted track (long
#: stripes and dashed lines brighter than the floor, and its grain); "glossy" a bright floor with broad reflections
#: of ceiling lamps; "cluttered" a room's clutter (chair legs, glints on metal, some lined up).
Floor = Literal["wall", "painted", "glossy", "cluttered"]


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
        led_diameter_mm: the LEDs' glowing diffusers' diameter (0: points).
        led_peak_mm: the distance ``led_peak`` is quoted at, mm (None: each camera's median distance of the wand).
        optics: every camera's lens (a fisheye seeing LEDs far beyond saturation blooms widely).
        window_on_path: the window's edge (where there is one) placed across the wand's path.
        floor: what lies behind the wand besides lamps and windows (:data:`Floor`).
        saturated_shift_px: saturated LED spots drawn this far outward from the principal point (a bias on purpose).
    """

    sensor: Sensor = field(default_factory=Sensor)
    lamps: int = 2
    windows: str = "one"
    lamp_near_path: bool = False
    lamp_row: bool = False
    led_peak: float = 400.0
    led_falloff: float = 3.0
    led_colour: tuple[float, float, float] = (1.0, 1.0, 1.0)
    led_peak_mm: float | None = None
    led_diameter_mm: float = 0.0
    optics: Optics = field(default_factory=Optics)
    window_on_path: bool = False
    floor: Floor = "wall"
    saturated_shift_px: float = 0.0


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
            across = _across_path(uv, size, (w, h), rng) if options.window_on_path else None
            u0, v0 = (u0, v0) if across is None else across
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
        room = CameraRoom(
            sensor=options.sensor,
            optics=options.optics,
            lamps=tuple(lamps),
            windows=tuple(windows),
            wall_gradient=(float(rng.uniform(-0.5, 0.5)), float(rng.uniform(-0.5, 0.5))),
            led_peak=options.led_peak / REFERENCE_EXPOSURE_MS,
            led_distance_mm=distances_mm[c] if options.led_peak_mm is None else options.led_peak_mm,
            led_falloff=options.led_falloff,
            led_colour=options.led_colour,
            led_diameter_mm=options.led_diameter_mm,
            saturated_shift_px=options.saturated_shift_px,
            optical_centre=(float(camera.model.principal_point[0]), float(camera.model.principal_point[1])),
        )
        rooms.append(room if options.floor == "wall" else _with_floor(room, options.floor, size, rng))
    return tuple(rooms)


def _across_path(
    uv: FloatArray, size: tuple[int, int], extent: tuple[float, float], rng: np.random.Generator
) -> tuple[float, float] | None:
    """The top-left corner of a window of ``extent`` (w, h) whose left or right edge runs through a point of the
    path of one LED (B), the window inside the image; None when the path gives no such point."""
    width, height = size
    w, h = extent
    track = uv[:, 1]
    track = track[np.all(np.isfinite(track), axis=1)]
    for _ in range(200):
        if not len(track):
            return None
        u, v = track[int(rng.integers(0, len(track)))]
        u0 = u if rng.random() < 0.5 else u - w  # the path crosses its left (or right) edge
        v0 = v - rng.uniform(0.2, 0.8) * h
        if 5 <= u0 <= width - w - 5 and 5 <= v0 <= height - h - 5:
            return float(u0), float(v0)
    return None


def _with_floor(room: CameraRoom, floor: Floor, size: tuple[int, int], rng: np.random.Generator) -> CameraRoom:
    """The room with its floor's static structure (:data:`Floor`), levels as seen at the room's exposure."""
    width, height = size
    exposure = room.sensor.exposure_ms
    seed = int(rng.integers(0, 2**31))
    if floor == "painted":  # a floor at 40-60, a track's lines (some dashed) 30-80 brighter, converging
        vanishing = np.array([rng.uniform(-0.5, 1.5) * width, rng.uniform(-1.5, -0.6) * height])
        stripes: list[Stripe] = []
        for _ in range(int(rng.integers(4, 7))):
            foot = np.array([rng.uniform(-0.2, 1.2) * width, 1.3 * height])
            start, end = vanishing + 0.55 * (foot - vanishing), foot
            level, wide = rng.uniform(30.0, 80.0) / exposure, rng.uniform(3.0, 10.0)
            if rng.random() < 0.5:  # dashed: dashes of 15-40 px with gaps of 15-40 px
                along = end - start
                length = float(np.linalg.norm(along))
                dash, gap, t = rng.uniform(15.0, 40.0), rng.uniform(15.0, 40.0), rng.uniform(0.0, 30.0)
                while t < length:
                    a, b = start + along * t / length, start + along * min(t + dash, length) / length
                    stripes.append(Stripe((float(a[0]), float(a[1])), (float(b[0]), float(b[1])), wide, level))
                    t += dash + gap
            else:
                stripes.append(Stripe((float(start[0]), float(start[1])), (float(end[0]), float(end[1])), wide, level))
        return replace(room, wall_level=rng.uniform(40.0, 60.0) / exposure, stripes=tuple(stripes), grain=0.06,
                       grain_seed=seed, vignetting=0.2)  # fmt: skip
    if floor == "glossy":  # a floor at 40-60 with two to four broad reflections reaching 130-190
        glows = tuple(
            Reflection(
                (float(rng.uniform(0.1, 0.9) * width), float(rng.uniform(0.1, 0.9) * height)),
                (float(rng.uniform(25.0, 70.0)), float(rng.uniform(25.0, 70.0))),
                float(rng.uniform(90.0, 130.0) / exposure),
            )
            for _ in range(int(rng.integers(2, 5)))
        )
        return replace(room, wall_level=rng.uniform(40.0, 60.0) / exposure, reflections=glows, grain=0.04,
                       grain_seed=seed, vignetting=0.2)  # fmt: skip
    # cluttered: chair legs and table edges a little brighter than the wall, glints on metal, some of them in a row
    legs = []
    for _ in range(int(rng.integers(4, 9))):
        u, v = rng.uniform(0.05, 0.95) * width, rng.uniform(0.3, 0.95) * height
        tilt, length = rng.uniform(-0.3, 0.3), rng.uniform(40.0, 150.0)
        bottom = (float(u + tilt * length), float(min(v + length, height + 10)))
        wide, level = float(rng.uniform(3.0, 6.0)), float(rng.uniform(15.0, 50.0) / exposure)
        legs.append(Stripe((float(u), float(v)), bottom, wide, level))
    glints = [
        Lamp((float(rng.uniform(10, width - 10)), float(rng.uniform(10, height - 10))), float(rng.uniform(0.6, 1.5)),
             float(rng.uniform(60.0, 400.0) / exposure * 4.0), flicker=float(rng.uniform(0.0, 0.03)))
        for _ in range(int(rng.integers(6, 13)))
    ]  # fmt: skip
    for leg in legs[:2]:  # glints along an edge: three or four lined up, unevenly spaced
        (u0, v0), (u1, v1) = leg.start, leg.end
        for t in np.sort(rng.uniform(0.0, 1.0, size=int(rng.integers(3, 5)))):
            centre = (float(u0 + t * (u1 - u0)), float(min(v0 + t * (v1 - v0), height - 10)))
            glints.append(Lamp(centre, float(rng.uniform(0.6, 1.2)), float(rng.uniform(100.0, 300.0) / exposure * 4.0),
                               flicker=0.02))  # fmt: skip
    return replace(room, lamps=room.lamps + tuple(glints), stripes=tuple(legs), grain=0.03, grain_seed=seed)


#: A fisheye lens seeing LEDs far beyond saturation: a wide bloom (a 10-20 px halo around an LED 8-30x over full scale).
BLOOMING = Optics(core_sigma_px=1.0, bloom=(0.25, 8.0), glare=(0.06, 20.0))
#: An LED 1 m away, on axis, at REFERENCE_EXPOSURE_MS: eight times full scale (in a small room, the wand 0.4-1.4 m
#: from the cameras, 1-30x as it turns and nears).
NEAR_LED_PEAK = 16.0 * 253.0
#: The diameter of a wand's diffused LED ball, mm (near a fisheye, 5-10 px across).
NEAR_LED_MM = 5.0

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
    "near_fisheye": lambda: RoomOptions(Sensor(exposure_ms=6.0), led_peak=NEAR_LED_PEAK, led_peak_mm=1000.0,
                                        led_diameter_mm=NEAR_LED_MM, optics=BLOOMING, window_on_path=True),
    "near_biased": lambda: RoomOptions(Sensor(exposure_ms=6.0), led_peak=NEAR_LED_PEAK, led_peak_mm=1000.0,
                                       led_diameter_mm=NEAR_LED_MM, optics=BLOOMING, window_on_path=True,
                                       saturated_shift_px=0.5),
    "cluttered": lambda: RoomOptions(Sensor(exposure_ms=6.0), floor="cluttered"),
    "painted_floor": lambda: RoomOptions(Sensor(exposure_ms=12.0, encoding="bgr8"), lamps=0, windows="none",
                                         floor="painted", led_peak=150.0),
    "glossy_floor": lambda: RoomOptions(Sensor(exposure_ms=12.0, encoding="bgr8"), lamps=0, windows="none",
                                        floor="glossy", led_peak=45.0),
}  # fmt: skip
#: The rig of each scene (:data:`wand_calib_ros.sim.scenarios.SCENARIOS`) where it is not the paper's three fisheyes.
ROOM_RIGS = {
    "colour_jpeg": "mixed",
    "near_fisheye": "small_room",
    "near_biased": "small_room",
    "painted_floor": "conventional",
    "glossy_floor": "conventional",
}


def scene_scenario(scene: str) -> Scenario:
    """The rig a named scene is rendered on (:data:`ROOM_RIGS`; the paper's three fisheyes by default)."""
    return SCENARIOS[ROOM_RIGS.get(scene, "paper3")]()
