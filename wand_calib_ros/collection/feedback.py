"""What a live collection tells the person waving the wand, as diagnostics values: each camera's timing and the
running estimate's figures (the collector puts them into /diagnostics)."""

from __future__ import annotations

from wand_calib_ros.collection.estimate import Estimate
from wand_calib_ros.collection.sync import FrameSynchroniser
from wand_calib_ros.core.model.result import CalibrationResult


def timing_values(sync: FrameSynchroniser, camera: str, result: CalibrationResult | None) -> dict[str, str]:
    """Diagnostics values of a camera's timing: its learned rate, its phase against the frames' anchor
    camera, the images whose frame had gone, and the last calibration's time offset (the images its time line
    passed over are its stream's values: :meth:`wand_calib_ros.collection.timeline.TimeLines.values`)."""
    values: dict[str, str] = {}
    period, phase = sync.period_ns(camera), sync.phase_ns(camera)
    if period is not None:
        values["frame_rate_hz"] = f"{1e9 / period:.2f}"
    if phase is not None:
        values["phase_ms"] = f"{phase / 1e6:+.2f}"
    if sync.stats.late.get(camera):
        values["late_images"] = str(sync.stats.late[camera])
    if result is not None and result.timing is not None:
        calibrated = result.camera(camera)
        scale, unit = (1000.0, "ms") if result.timing.unit == "s" else (1.0, "frames")
        for key, label, value in (("time_offset", "time_offset", calibrated.time_offset),
                                  ("readout", "readout", calibrated.readout)):  # fmt: skip
            std = calibrated.parameter_std.get(key)
            values[f"{label}_{unit}"] = f"{scale * value:+.3f}" + ("" if std is None else f" +- {scale * std:.3f}")
    return values


def estimate_values(
    estimate: Estimate | None, failure: str | None, now: float
) -> tuple[dict[str, dict[str, str]], dict[str, str]]:
    """Diagnostics values of the running estimate: per camera its image error, focal and
    principal-point uncertainty and whether they still fall; for the rig its grade, wand error, age
    and frames (or why there is none yet)."""
    if estimate is None or estimate.round.result is None:
        return {}, {"estimate": failure or "waiting for enough frames"}
    result = estimate.round.result
    cameras: dict[str, dict[str, str]] = {}
    if result.quality is not None:
        for camera in result.quality.cameras:
            cameras[camera.name] = {
                "estimate_rms_px": f"{camera.image_error_px:.3f}",
                "estimate_focal_std_percent": f"{camera.focal_std_percent:.3f}",
                "estimate_principal_std_px": f"{camera.principal_std_px:.2f}",
                "estimate_improving": "yes" if estimate.improving.get(camera.name, True) else "no",
            }
    rig = {
        "estimate": "preliminary" if failure is None else f"preliminary; the newest round failed: {failure}",
        "estimate_grade": "-" if result.quality is None else result.quality.grade,
        "estimate_wand_rms_mm": f"{result.wand_length_rms_mm:.3f}",
        "estimate_age_s": f"{now - estimate.finished:.0f}",
        "estimate_frames": str(estimate.round.frames),
        "estimate_seconds": f"{estimate.round.seconds:.2f}",
    }
    return cameras, rig
