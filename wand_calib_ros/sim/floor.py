"""The floor of a simulated room as a user shows it to the cameras: the wand laid still on it along x,
then along y, or a floor tool (an L-frame) with markers at known positions lying at the origin."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.placements import triangulate_placements
from wand_calib_ros.core.model.camera_model import CameraModel, project
from wand_calib_ros.core.model.geometry import Pose
from wand_calib_ros.core.model.result import WorldFrame
from wand_calib_ros.core.model.rig import WandObservations
from wand_calib_ros.sim.scenarios import Scenario, image_placements, visible

FloatArray = NDArray[np.float64]

#: Frames per lay: the wand held still for half a second at 30 fps.
STILL_FRAMES = 15


@dataclass(frozen=True, eq=False)
class FloorTruth:
    """Floor frames and the world frame they define.

    Attributes:
        observations: the floor frames' views (the wand's or the tool's markers as points).
        world_from_reference: X_world = R X_ref + T of the true world (z up, origin and x as the floor
            defines them).
    """

    observations: WandObservations
    world_from_reference: Pose


def _frame(scenario: Scenario) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    if scenario.floor is None:
        raise ValueError(f"scenario {scenario.name} has no floor")
    point, normal, x = scenario.floor
    return point, normal, x, np.cross(normal, x)


def _world(origin: FloatArray, normal: FloatArray, x: FloatArray) -> Pose:
    rotation = np.stack([x, np.cross(normal, x), normal])
    return Pose(rotation, -rotation @ origin)


def floor_lays(
    scenario: Scenario, noise_px: float, rng: np.random.Generator, *, frames: int = STILL_FRAMES, first_frame: int = 0
) -> FloorTruth:
    """The wand laid still on the floor along x (its A at the origin), then along y beside it.

    The LEDs of a wand lying on the floor are seen from everywhere above it.
    """
    point, normal, x, y = _frame(scenario)
    length = scenario.wand.L
    lays = [(point - 0.5 * length * x, x), (point + 150.0 * x - 0.5 * length * y, y)]
    a = np.repeat([lay[0] for lay in lays], frames, axis=0)
    direction = np.repeat([lay[1] for lay in lays], frames, axis=0)
    lying = replace(scenario, led_cone_deg=None)
    data = image_placements(lying, a, direction, np.tile(normal, (len(a), 1)), noise_px, rng, first_frame=first_frame)
    return FloorTruth(data.observations, _world(lays[0][0], normal, x))


def floor_tool(
    scenario: Scenario,
    points_mm: FloatArray,
    noise_px: float,
    rng: np.random.Generator,
    *,
    frames: int = STILL_FRAMES,
    first_frame: int = 0,
) -> FloorTruth:
    """A floor tool with markers at ``points_mm`` (K, 3; its own frame is the world's) lying under the volume.

    The world origin is the floor's point under the volume's centre, x along the room's x.
    """
    point, normal, x, _ = _frame(scenario)
    world = _world(point, normal, x)
    markers = world.inverse().apply(np.asarray(points_mm, dtype=float))  # (K, 3) in the reference frame
    uv = np.full((frames, len(scenario.cameras), len(markers), 2), np.nan)
    for c, camera in enumerate(scenario.cameras):
        seen = visible(camera, markers)
        uv[:, c, seen] = project(camera.model, camera.pose.apply(markers[seen]))
    uv = uv + rng.normal(scale=noise_px, size=uv.shape) if noise_px > 0 else uv
    names = tuple(c.spec.name for c in scenario.cameras)
    return FloorTruth(WandObservations(np.arange(first_frame, first_frame + frames), names, uv), world)


def shuffled(truth: FloorTruth, rng: np.random.Generator) -> FloatArray:
    """(F, C, K, 2) the floor views with each view's points in a random order, as a detector finds a
    tool's blobs."""
    uv = truth.observations.uv.copy()
    for f in range(uv.shape[0]):
        for c in range(uv.shape[1]):
            uv[f, c] = uv[f, c][rng.permutation(uv.shape[2])]
    return uv


def world_errors(
    scenario: Scenario,
    world: WorldFrame,
    models: tuple[CameraModel, ...],
    poses: tuple[Pose, ...],
    truth: FloorTruth,
    *,
    extent_mm: float = 1000.0,
) -> dict[str, float]:
    """A world frame's errors against the truth, two ways.

    - ``normal`` (deg) and ``origin`` (mm): as the result states the world, relative to the reference
      camera (so every camera's pose in the world), with ``z normal`` and ``z origin`` the errors over the
      reported standard deviations;
    - ``measured normal`` and ``measured origin``: the true floor (a grid of +- ``extent_mm``) and origin
      imaged without noise by the true cameras, triangulated with the calibrated ones and put into the
      result's world: the tilt of that floor and where the origin lands (what a marker put there reads).
    """
    estimated, true = world.world_from_reference, truth.world_from_reference
    normal = float(np.degrees(np.arccos(np.clip(estimated.rotation[2] @ true.rotation[2], -1.0, 1.0))))
    origin = float(np.linalg.norm(estimated.inverse().translation - true.inverse().translation))
    steps = np.linspace(-extent_mm, extent_mm, 5)
    grid = np.array([[x, y, 0.0] for x in steps for y in steps] + [[0.0, 0.0, 0.0]])
    points = true.inverse().apply(grid)
    uv = np.full((len(points), len(scenario.cameras), 1, 2), np.nan)
    for c, camera in enumerate(scenario.cameras):
        uv[:, c, 0] = project(camera.model, camera.pose.apply(points))
    measured = estimated.apply(triangulate_placements(models, poses, uv)[:, 0])
    centred = measured[:-1] - measured[:-1].mean(axis=0)
    tilt = float(np.degrees(np.arccos(abs(np.linalg.svd(centred)[2][2, 2]))))
    return {
        "normal": normal,
        "origin": origin,
        "z normal": normal / world.normal_std_deg,
        "z origin": origin / world.origin_std_mm,
        "measured normal": tilt,
        "measured origin": float(np.linalg.norm(measured[-1])),
    }
