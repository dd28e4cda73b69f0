"""A rendered take: the wand's LEDs through each camera of a rig over time, in its room, with the truth."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.model.camera_model import CameraModel, project
from wand_calib_ros.core.model.rig import WandObservations
from wand_calib_ros.sim.clocks import CameraClock, film, stamp_ns, synchronised_clocks
from wand_calib_ros.sim.motion import WavedWand, shared_volume, waved_wand
from wand_calib_ros.sim.room import LAMP_MARGIN_PX, CameraRoom, CameraTruth, RoomRecording
from wand_calib_ros.sim.room_images import render_camera, scene_level
from wand_calib_ros.sim.room_layout import RoomOptions, room_for
from wand_calib_ros.sim.scenarios import Scenario, visibility

FloatArray = NDArray[np.float64]


def _falloff(to_camera: FloatArray, direction: FloatArray, power: float) -> FloatArray:
    """sin(a)^p of the angle a between the wand's direction and the line of sight (a floor of 1e-3)."""
    cosine = np.einsum("...i,...i->...", to_camera, direction) / np.linalg.norm(to_camera, axis=-1)
    return np.maximum(np.sqrt(np.clip(1.0 - cosine**2, 0.0, 1.0)), 1e-3) ** power


def _exposure_steps(streak_px: float) -> int:
    """Steps along a motion streak: about two per pixel of its length (smooth under a 1 px core)."""
    return int(np.clip(np.ceil(2.0 * streak_px) + 1, 3, 200))


def _led_light(
    scenario: Scenario, camera: int, room: CameraRoom, trajectory: WavedWand, times: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(M, K, 2) pixels, (M, K) light (grey levels x px per ms) and (M, K) image radius (px) of the LEDs at
    ``times`` (NaN: not seen)."""
    true_camera = scenario.cameras[camera]
    motion = trajectory.at(times)
    points = motion.points(scenario.wand)  # (M, K, 3)
    in_camera = true_camera.pose.apply(points)
    uv = project(true_camera.model, in_camera)
    radius = _image_radius(true_camera.model, in_camera, uv, 0.5 * room.led_diameter_mm)
    seen = visibility(scenario, motion.wand_a, motion.direction, motion.facing)[:, camera]
    distance = np.linalg.norm(in_camera, axis=-1)
    to_camera = true_camera.pose.center[None, None, :] - points
    falloff = _falloff(to_camera, motion.direction[:, None, :], room.led_falloff)
    core = room.optics.terms()[0][0]
    energy = room.led_peak / core * 2 * np.pi * room.optics.core_sigma_px**2
    light = energy * (room.led_distance_mm / distance) ** 2 * falloff
    return np.where(seen[..., None], uv, np.nan), np.where(seen, light, np.nan), radius


def _image_radius(model: CameraModel, in_camera: FloatArray, uv: FloatArray, radius_mm: float) -> FloatArray:
    """(...) the image radius (px) of a glowing ball of ``radius_mm`` at (..., 3) points of the camera's frame, whose
    (..., 2) images are ``uv``: the mean of its image extent along two directions across the line of sight."""
    if radius_mm <= 0.0:
        return np.zeros(in_camera.shape[:-1])
    ray = in_camera / np.linalg.norm(in_camera, axis=-1, keepdims=True)
    first = np.cross(ray, [1.0, 0.0, 0.0])
    first /= np.maximum(np.linalg.norm(first, axis=-1, keepdims=True), 1e-12)
    second = np.cross(ray, first)
    extents = [np.linalg.norm(project(model, in_camera + radius_mm * e) - uv, axis=-1) for e in (first, second)]
    return np.asarray(0.5 * (extents[0] + extents[1]))


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
        ends, _, _ = _led_light(
            scenario, c, room, trajectory, np.concatenate([mids - exposure_s / 2, mids + exposure_s / 2])
        )
        streak = np.linalg.norm(ends[: len(mids)] - ends[len(mids) :], axis=-1)  # (N, K)
        paths, energies, radii = [], [], []
        for i, mid in enumerate(mids):
            longest = float(np.nanmax(streak[i])) if np.isfinite(streak[i]).any() else 0.0
            steps = _exposure_steps(longest)
            times = mid + exposure_s * (np.arange(steps) / (steps - 1) - 0.5)
            uv, light, radius = _led_light(scenario, c, room, trajectory, times)
            paths.append(np.transpose(uv, (1, 0, 2)))
            energies.append(light.T * room.sensor.exposure_ms / steps)
            radii.append(radius[steps // 2])
        images, encoding, peaks, light = render_camera(room, size, paths, energies, rng, radii)
        uv_mid = take.uv
        behind = _sample(light, uv_mid)
        static_level = _sample(scene_level(room, size), uv_mid)
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
                np.where(np.isfinite(uv_mid[..., 0]), peaks, 0.0),
                255.0 - room.sensor.black_level,
            )
        )
        for stamp, image in zip(stamp_ns(take.stamps), images, strict=True):
            frames.append((int(stamp), c, camera.spec.name, image, encoding))
    frames.sort(key=lambda f: (f[0], f[1]))
    return RoomRecording([(name, stamp, image, enc) for stamp, _, name, image, enc in frames], tuple(truths), rooms)


def _sample(image: FloatArray, uv: FloatArray) -> FloatArray:
    """``image`` at the nearest pixel of each (..., 2) point (0 where not finite)."""
    height, width = image.shape
    finite = np.all(np.isfinite(uv), axis=-1)
    u = np.clip(np.round(np.where(finite, uv[..., 0], 0)).astype(int), 0, width - 1)
    v = np.clip(np.round(np.where(finite, uv[..., 1], 0)).astype(int), 0, height - 1)
    return np.where(finite, image[v, u], 0.0)


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
