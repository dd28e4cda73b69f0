"""Result YAML and ROS camera_info YAML files.

The result contract::

    reference_camera: cam0
    cameras:
      cam0:
        camera_model: equidistant        # or plumb_bob, rational_polynomial (then also lens_terms)
        k: [k1, k2, k3, k4, k5]          # mm, r(theta) = k1 theta + k2 theta^3 + ... (tan(theta) for pinholes)
        m: [mu, mv]                      # px/mm (fixed from the pixel size)
        principal_point: [u0, v0]        # px, OpenCV convention
        rotation: [[...], [...], [...]]  # X_cam = R X_ref + T
        translation: [tx, ty, tz]        # mm
        rms_reprojection_px: ...
        image_size: [w, h]
        opencv: {distortion_model: equidistant, camera_matrix: 3x3, distortion: [D1..D4]}
        opencv_equidistant: {camera_matrix: 3x3, distortion: [D1..D4]}   # equidistant cameras only
        std: {k1: ..., u0: ..., rx: ..., tx: ..., time_offset_s: ...}
        time_offset_s: ...               # exposure = stamp - time_offset_s (time_offset_frames without stamps);
                                         # only where estimated (absent: 0)
        rolling_shutter_readout_s: ...   # row v is exposed readout * v / H later; only where estimated or
                                         # given (absent: 0, a global shutter)
        ...
    timing: {unit: s, time_offsets: estimated, rolling_shutter: {cam0: fixed}, frame_period_s: ...}
    metrics: {...}
    warnings: [...]
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from wand_calib_ros.core.errors import ModelError
from wand_calib_ros.core.model.brightness import BIAS_EDGES, class_text
from wand_calib_ros.core.model.camera_model import EQUIDISTANT, CameraModel, to_opencv
from wand_calib_ros.core.model.geometry import Pose
from wand_calib_ros.core.model.result import CalibrationResult, ClassBias
from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.outputs import write_together
from wand_calib_ros.io.rig_yaml import wand_dict
from wand_calib_ros.io.text import read_yaml

CONVENTIONS = {
    "frames": "X_cam = R X_ref + T, mm; reference = reference_camera",
    "pixels": "OpenCV: (0, 0) is the centre of the top-left pixel",
    "model": "r(theta) = k1 theta + k2 theta^3 + k3 theta^5 + k4 theta^7 + k5 theta^9 (mm); "
    "u = mu r cos(phi) + u0, v = mv r sin(phi) + v0",
    "equivalence": "exactly OpenCV fisheye / ROS 'equidistant': fx = k1 mu, fy = k1 mv, cx = u0, cy = v0, "
    "D = [k2, k3, k4, k5] / k1",
    "pinhole_models": "plumb_bob / rational_polynomial cameras: r(s) = (k1 s + k2 s^3 + k3 s^5 + k4 s^7) / "
    "(1 + d1 s^2 + d2 s^4 + d3 s^6), s = tan(theta), plus the tangential t1, t2 (mm; lens_terms = [t1, t2, d1, "
    "d2, d3]): OpenCV's k1, k2, k3 = [k2, k3, k4] / k1, p1, p2 = [t1, t2] / k1, k4..k6 = d1..d3 (see opencv)",
    "identifiable": "only k1 mu, k1 mv and k_i / k1 are determined by images; m comes from the pixel size",
}


def _floats(values: Any) -> Any:
    array = np.asarray(values, dtype=np.float64)
    return array.tolist()


def camera_entry(model: CameraModel, pose: Pose) -> dict[str, Any]:
    """The geometric part of one camera's result entry."""
    opencv = to_opencv(model)
    entry: dict[str, Any] = {
        "camera_model": model.distortion_model,
        "k": _floats(model.k),
        "m": _floats(model.m),
        "principal_point": _floats(model.principal_point),
        "rotation": _floats(pose.rotation),
        "translation": _floats(pose.translation),
        "image_size": list(model.image_size),
    }
    if model.is_pinhole:
        entry["lens_terms"] = _floats(model.lens_vector())
    entry["opencv"] = {
        "distortion_model": opencv.distortion_model,
        "camera_matrix": _floats(opencv.camera_matrix),
        "distortion": _floats(opencv.distortion),
    }
    if model.distortion_model == EQUIDISTANT:  # the key results had before the pinhole models
        entry["opencv_equidistant"] = {
            "camera_matrix": _floats(opencv.camera_matrix),
            "distortion": _floats(opencv.distortion),
        }
    return entry


def timing_keys(unit: str) -> dict[str, str]:
    """Result keys of the core's timing parameters for observations in ``unit`` ("s" or "frames")."""
    return {"time_offset": f"time_offset_{unit}", "readout": f"rolling_shutter_readout_{unit}"}


def _world_dict(result: CalibrationResult) -> dict[str, Any]:
    """The ``world`` block: the floor's frame and every camera in it, or a note that there is none."""
    world = result.world
    if world is None:
        return {"frame": "reference_camera", "note": f"no floor given: poses are relative to {result.reference_camera}"}
    cameras = {}
    for camera in result.cameras:
        pose = world.camera_in_world(camera.pose)
        cameras[camera.name] = {"rotation": _floats(pose.rotation), "translation": _floats(pose.translation)}
    return {
        "frame": "floor",
        "rotation": _floats(world.world_from_reference.rotation),
        "translation": _floats(world.world_from_reference.translation),
        "floor": {
            "placements": int(world.placements),
            "residual_mm": float(world.residual_mm),
            "normal_std_deg": float(world.normal_std_deg),
            "origin_std_mm": float(world.origin_std_mm),
        },
        "cameras": cameras,
    }


def result_to_dict(result: CalibrationResult) -> dict[str, Any]:
    """The result YAML document."""
    cameras: dict[str, Any] = {}
    timing = result.timing
    keys = timing_keys("frames" if timing is None else timing.unit)
    for camera in result.cameras:
        entry = camera_entry(camera.model, camera.pose)
        entry.update(
            {
                "rms_reprojection_px": float(camera.rms_reprojection_px),
                "rms_reprojection_2d_px": float(np.sqrt(2.0) * camera.rms_reprojection_px),
                "n_observations": int(camera.n_observations),
                "n_views": int(camera.n_views),
                "rejected_views": int(camera.rejected_views),
                "std": {keys.get(k, k): float(v) for k, v in camera.parameter_std.items()},
                "radial_covariance": _floats(camera.radial_covariance),
                "max_observed_theta_deg": float(camera.max_observed_theta_deg),
                "intrinsics": camera.intrinsics,
                "initial_projection": camera.initial_projection,
                "fixed_coefficients": list(camera.fixed_coefficients),
            }
        )
        # Timing keys only for what was estimated (or set: a rig description's readout_ms); absent means 0.
        if timing is not None and (timing.time_offsets == "estimated" or camera.time_offset != 0.0):
            entry[keys["time_offset"]] = float(camera.time_offset)
        if timing is not None and (timing.rolling_shutter.get(camera.name) == "estimated" or camera.readout != 0.0):
            entry[keys["readout"]] = float(camera.readout)
        if camera.centre_bias:  # (absent: no bias found, or no brightness known)
            entry["centre_bias"] = [_bias_dict(bias) for bias in camera.centre_bias]
        cameras[camera.name] = entry
    return {
        "reference_camera": result.reference_camera,
        "conventions": dict(CONVENTIONS),
        "wand": wand_dict(result.wand),
        "cameras": cameras,
        "metrics": {
            "wand_length_rms_mm": float(result.wand_length_rms_mm),
            "wand_length_mean_mm": float(result.wand_length_mean_mm),
            "wand_length_std_mm": float(result.wand_length_std_mm),
            "sigma_px": float(result.sigma_px),
            "residuals": int(result.dof[0]),
            "free_parameters": int(result.dof[1]),
            "placements_used": int(result.placements_used),
            "placements_rejected": int(result.placements_rejected),
            "iterations": int(result.iterations),
        },
        "timing": _timing_dict(result),
        "world": _world_dict(result),
        "quality": _quality_dict(result),
        "lens_trials": [
            {"projections": list(t.projections), "wand_rms_mm": float(t.wand_rms_mm)}
            | ({"failure": t.failure} if t.failure else {})
            for t in result.lens_trials
        ],
        "clock_offsets": {
            o.camera: {
                "offset_frames": float(o.offset_frames),
                "correlation": float(o.correlation),
                "rms_px": float(o.rms_px),
                "rms_corrected_px": float(o.rms_corrected_px),
                "points": int(o.points),
            }
            for o in result.clock_offsets
        },
        "warnings": list(result.warnings),
    }


def _bias_dict(bias: ClassBias) -> dict[str, Any]:
    """One brightness class's corrected centre bias (docs/formats.md, ``centre_bias``)."""
    return {
        "brightness": class_text(bias.klass),
        "from_stops": float(BIAS_EDGES[bias.klass - 1]),
        "u_px": float(bias.offset_px[0]),
        "v_px": float(bias.offset_px[1]),
        "radial_px": float(bias.radial_px),
        "std_px": [float(x) for x in bias.std_px],
        "points": int(bias.points),
        "shape": bias.shape,
    }


def _quality_dict(result: CalibrationResult) -> dict[str, Any] | None:
    """The verdict (docs/quality-and-repair.md): grade, world and image errors, what limits the grade."""
    verdict = result.quality
    if verdict is None:
        return None
    return {
        "grade": verdict.grade,
        "world_error_mm": float(verdict.world_error_mm),
        "world_noise_mm": float(verdict.world_noise_mm),
        "noise_px": float(verdict.noise_px),
        "cameras": {
            c.name: {
                "image_error_px": float(c.image_error_px),
                "noise_ratio": float(c.noise_ratio),
                "focal_std_percent": float(c.focal_std_percent),
                "principal_std_px": float(c.principal_std_px),
            }
            for c in verdict.cameras
        },
        "limited_by": list(verdict.limited_by),
    }


def _timing_dict(result: CalibrationResult) -> dict[str, Any]:
    """How the cameras' timing was treated (unit, estimated or fixed, the recording's frame period)."""
    timing = result.timing
    if timing is None:
        return {
            "unit": "frames",
            "time_offsets": "fixed",
            "rolling_shutter": {c.name: "fixed" for c in result.cameras},
            "note": "views of a frame taken as simultaneous",
        }
    described: dict[str, Any] = {
        "unit": timing.unit,
        "time_offsets": timing.time_offsets,
        "rolling_shutter": dict(timing.rolling_shutter),
        f"frame_period_{timing.unit}": float(timing.frame_period),
        "notes": list(timing.notes),
    }
    if timing.clocks:
        described["clocks"] = list(timing.clocks)
    return described


#: libyaml's emitter where PyYAML has it: the same text as the pure-Python one, 4x faster (a result file
#: of 16 cameras in 8 ms instead of 30 ms).
_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


def yaml_text(document: dict[str, Any]) -> str:
    """A YAML document as text (block style, keys in insertion order)."""
    return yaml.dump(document, Dumper=_DUMPER, sort_keys=False, default_flow_style=None, width=120)


def write_yaml(document: dict[str, Any], path: str | Path) -> None:
    """Write a YAML document (replacing the file only once it is written whole)."""
    write_together({Path(path): yaml_text(document)})


def write_result(result: CalibrationResult, path: str | Path) -> None:
    """Write the result YAML."""
    write_yaml(result_to_dict(result), path)


def calibration_paths(
    camera_names: Iterable[str], result_path: str | Path, camera_info_dir: str | Path | None
) -> list[Path]:
    """The files :func:`write_calibration` writes: the result, then ``<camera>.yaml`` per camera."""
    infos = [] if camera_info_dir is None else [Path(camera_info_dir) / f"{name}.yaml" for name in camera_names]
    return [Path(result_path), *infos]


def write_calibration(
    result: CalibrationResult, result_path: str | Path, camera_info_dir: str | Path | None = None
) -> list[Path]:
    """Write the result YAML and (into ``camera_info_dir``) each camera's camera_info YAML as one set:
    every file is in place, or (OutputError) none was replaced. Returns the paths written."""
    paths = calibration_paths([c.name for c in result.cameras], result_path, camera_info_dir)
    documents = [result_to_dict(result), *(camera_info_dict(c.name, c.model) for c in result.cameras)]
    write_together({path: yaml_text(document) for path, document in zip(paths, documents, strict=False)})
    return paths


@dataclass(frozen=True, eq=False)
class CameraGeometry:
    """Intrinsics, pose and timing of one camera as read from a result (or truth) file.

    Attributes:
        model: intrinsics.
        pose: X_cam = R X_ref + T, mm.
        time_offset: exposure = stamp - time_offset, in the file's time unit (0 when absent).
        readout: rolling-shutter readout time in the file's time unit (0 when absent).
    """

    model: CameraModel
    pose: Pose
    time_offset: float = 0.0
    readout: float = 0.0


def read_result(path: str | Path) -> tuple[str, dict[str, CameraGeometry]]:
    """Read the geometry of a result YAML: (reference camera, per-camera model, pose and timing).

    The timing is read in the file's unit: ``time_offset_s`` / ``rolling_shutter_readout_s``, or their
    ``_frames`` forms.

    Raises:
        FormatError: one line naming the file and what it is not (a rig description, an empty file, a
            camera without its model or pose, a rotation that is not one, ...).
    """
    path = Path(path)
    return result_geometry(result_document(path), path)


def result_geometry(data: dict[str, Any], path: Path) -> tuple[str, dict[str, CameraGeometry]]:
    """:func:`read_result` of a result's mapping (as :func:`result_document` returns it, or
    :func:`result_to_dict` makes it); ``path`` names it in errors.

    Raises:
        FormatError: as :func:`read_result`.
    """
    where = "the file"
    try:
        cameras = {}
        for name, entry in data["cameras"].items():
            where = f"camera '{name}'"
            pose = Pose(entry["rotation"], entry["translation"])
            _check_pose(path, str(name), pose)
            cameras[str(name)] = CameraGeometry(
                CameraModel(
                    entry["k"],
                    entry["m"],
                    entry["principal_point"],
                    tuple(entry["image_size"]),
                    str(entry.get("camera_model", EQUIDISTANT)),
                    entry.get("lens_terms"),
                ),
                pose,
                float(entry.get("time_offset_s", entry.get("time_offset_frames", 0.0))),
                float(entry.get("rolling_shutter_readout_s", entry.get("rolling_shutter_readout_frames", 0.0))),
            )
    except KeyError as error:
        raise FormatError(path, f"not a wand_calib_ros result file: {where} has no {error}") from None
    except (TypeError, ValueError, AttributeError, ModelError) as error:
        raise FormatError(path, f"not a wand_calib_ros result file: {where}: {error}") from None
    reference = str(data.get("reference_camera"))
    if reference not in cameras:
        raise FormatError(path, f"its reference_camera {reference!r} is not one of its cameras ({', '.join(cameras)})")
    return reference, cameras


def result_document(path: Path) -> dict[str, Any]:
    """The mapping of a result YAML with a non-empty ``cameras`` mapping (FormatError naming what it is not)."""
    data = read_yaml(path)
    if data is None:
        raise FormatError(path, "empty: not a wand_calib_ros result file")
    if not isinstance(data, dict):
        raise FormatError(path, f"not a wand_calib_ros result file (a YAML {type(data).__name__}, not a mapping)")
    cameras = data.get("cameras")
    if isinstance(cameras, list) and "wand" in data:
        raise FormatError(path, "not a wand_calib_ros result file (a rig description? its cameras are a list)")
    if not isinstance(cameras, dict):
        raise FormatError(path, "not a wand_calib_ros result file: no cameras mapping")
    if not cameras:
        raise FormatError(path, "no cameras in the result")
    return data


def _check_pose(path: Path, name: str, pose: Pose) -> None:
    """A camera's pose must be finite and its rotation a rotation (orthonormal, determinant 1)."""
    if not (np.all(np.isfinite(pose.rotation)) and np.all(np.isfinite(pose.translation))):
        raise FormatError(path, f"camera '{name}': its rotation must be finite numbers, and its translation")
    deviation = float(np.max(np.abs(pose.rotation.T @ pose.rotation - np.eye(3))))
    if deviation > 1e-6 or np.linalg.det(pose.rotation) < 0:
        raise FormatError(
            path, f"camera '{name}': its rotation is not a rotation matrix (R^T R differs from I by {deviation:.2g}, "
            f"det {np.linalg.det(pose.rotation):.3g})"
        )  # fmt: skip


def with_cameras_replaced(
    document: dict[str, Any], cameras: dict[str, tuple[CameraModel, Pose, float, dict[str, float]]], note: str
) -> dict[str, Any]:
    """A result document with some cameras re-estimated (``wand-calib refine``): per name (model, pose,
    per-coordinate RMS px, standard deviations of the re-estimated parameters); their poses in the
    world block follow, and ``note`` joins the warnings. Every other entry stays as it was."""
    out = dict(document)
    out["cameras"] = {name: dict(entry) for name, entry in document["cameras"].items()}
    world = document.get("world") or {}
    floor = world.get("frame") == "floor"
    if floor:
        out["world"] = {**world, "cameras": dict(world["cameras"])}
        world_from_reference = Pose(world["rotation"], world["translation"])
    for name, (model, pose, rms, std) in cameras.items():
        entry = out["cameras"][name]
        entry.update(camera_entry(model, pose))
        entry["rms_reprojection_px"] = float(rms)
        entry["rms_reprojection_2d_px"] = float(np.sqrt(2.0) * rms)
        entry["std"] = {**entry.get("std", {}), **{k: float(v) for k, v in std.items()}}
        if floor:
            in_world = pose.compose(world_from_reference.inverse())
            out["world"]["cameras"][name] = {
                "rotation": _floats(in_world.rotation),
                "translation": _floats(in_world.translation),
            }
    out["warnings"] = [*document.get("warnings", []), note]
    return out


def read_world_poses(path: str | Path) -> dict[str, Pose] | None:
    """Each camera's pose in the world (X_cam = R X_world + T, mm) from a result YAML's ``world`` block,
    or None when the calibration had no floor."""
    path = Path(path)
    world = read_yaml(path).get("world") or {}
    if world.get("frame") != "floor":
        return None
    try:
        return {str(n): Pose(e["rotation"], e["translation"]) for n, e in world["cameras"].items()}
    except (KeyError, TypeError, ValueError, AttributeError) as error:
        raise FormatError(path, f"world block: {error}") from None


def camera_info_dict(name: str, model: CameraModel) -> dict[str, Any]:
    """A ROS camera_calibration style camera_info YAML document in the camera's own model (``equidistant``,
    ``plumb_bob`` or ``rational_polynomial``)."""
    opencv = to_opencv(model)
    k = opencv.camera_matrix
    projection = np.hstack([k, np.zeros((3, 1))])
    return {
        "image_width": int(model.image_size[0]),
        "image_height": int(model.image_size[1]),
        "camera_name": name,
        "camera_matrix": {"rows": 3, "cols": 3, "data": _floats(k.ravel())},
        "distortion_model": opencv.distortion_model,
        "distortion_coefficients": {"rows": 1, "cols": int(opencv.distortion.size), "data": _floats(opencv.distortion)},
        "rectification_matrix": {"rows": 3, "cols": 3, "data": _floats(np.eye(3).ravel())},
        "projection_matrix": {"rows": 3, "cols": 4, "data": _floats(projection.ravel())},
    }
