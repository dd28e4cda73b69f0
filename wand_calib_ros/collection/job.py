"""What /calibrate and /refine do, without ROS: check coverage, calibrate (or repair a moved camera),
write the result files.

The observations come from the collector's persisted buffer file, so
``wand-calib calibrate`` on that file computes exactly the same result.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

# numpy loads these on first use, inside a calibration (the RANSAC sampler's numpy.random, numpy.ma
# through np.unique): loaded with the nodes that run jobs, a first /calibrate does not wait 23 ms for them.
import numpy.ma
import numpy.random

from wand_calib_ros.collection.buffer import BUFFER_FILE
from wand_calib_ros.collection.coverage import CoverageStatus, CoverageThresholds, CoverageTracker
from wand_calib_ros.collection.errors import CoverageError
from wand_calib_ros.collection.report_drawer import ReportRequest
from wand_calib_ros.core.after.repair import judge_moved, repair_moved, repaired_result
from wand_calib_ros.core.judge.quality import judge, noise_wand_error
from wand_calib_ros.core.model.result import CalibrationResult
from wand_calib_ros.core.model.rig import RigSpec, WandObservations
from wand_calib_ros.core.pipeline import CalibrationOptions, calibrate
from wand_calib_ros.io.errors import ExportError
from wand_calib_ros.io.export import WORLD_FORMATS, export
from wand_calib_ros.io.export.cameras import cameras_of
from wand_calib_ros.io.outputs import check_writable
from wand_calib_ros.io.result_yaml import calibration_paths, result_document, write_calibration

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class CalibrationFiles:
    """Where a calibration was written.

    Attributes:
        result: ``result.yaml`` (the core's result contract).
        camera_info: one camera_info YAML per camera (in its own model).
        exports: the files of the other tools' formats asked for (``export/<format>/``).
        export_failures: why a format asked for could not express this calibration (e.g. a fisheye
            as DLT coefficients); the rest is written.
    """

    result: Path
    camera_info: tuple[Path, ...]
    exports: tuple[Path, ...] = ()
    export_failures: tuple[str, ...] = ()


def report_request(
    rig: RigSpec, observations: WandObservations, files: CalibrationFiles, output_dir: Path, source: str
) -> ReportRequest:
    """The report of the calibration just written to ``files``, for a :class:`ReportDrawer`: into
    ``output_dir/report``, of the result read back as written (another calibration may replace the file
    while the report is drawn).

    Raises:
        FormatError: the result file cannot be read back.
    """
    document = result_document(files.result)
    return ReportRequest(
        rig, observations, files.result, document, output_dir / "report", output_dir / BUFFER_FILE, source
    )


def coverage_of(rig: RigSpec, observations: WandObservations, thresholds: CoverageThresholds) -> CoverageStatus:
    """Coverage of a set of observations (what the collector reports while waving)."""
    tracker = CoverageTracker(rig, thresholds)
    tracker.add(observations.uv)
    return tracker.status()


def run_calibration(
    rig: RigSpec,
    observations: WandObservations,
    output_dir: Path,
    *,
    thresholds: CoverageThresholds | None = None,
    options: CalibrationOptions = CalibrationOptions(),
    exports: tuple[str, ...] = (),
) -> tuple[CalibrationResult, CalibrationFiles]:
    """Calibrate and write ``result.yaml``, ``camera_info/<cam>.yaml`` and ``export/<format>/`` for each of
    ``exports`` (formats of :mod:`wand_calib_ros.io.export`); the report is drawn apart (:func:`report_request`).

    Args:
        rig: the rig description.
        observations: everything collected.
        output_dir: where the files go (created).
        thresholds: coverage required first (None: no check).
        options: calibration settings.

    Raises:
        CoverageError: the coverage is below ``thresholds`` (the message says what is missing).
        WandCalibError: the calibration itself failed (too few views, disconnected cameras, ...).
    """
    if thresholds is not None:
        status = coverage_of(rig, observations, thresholds)
        if not status.ready:
            raise CoverageError(status.messages())
    result_path = output_dir / "result.yaml"
    folders = [output_dir / "export" / name for name in exports]
    files_in_folders = [folder / "calibration" for folder in folders]  # a file's folder is what gets checked
    check_writable([*calibration_paths(rig.camera_names, result_path, output_dir / "camera_info"), *files_in_folders])
    result = calibrate(rig, observations, options)
    infos = tuple(write_calibration(result, result_path, output_dir / "camera_info")[1:])
    exported: list[Path] = []
    failures: list[str] = []
    for name, folder in zip(exports, folders, strict=True):
        try:
            exported += export(cameras_of(result, in_world=name in WORLD_FORMATS), name, folder)
        except ExportError as error:
            log.warning("the calibration is written, but its %s export failed: %s", name, error)
            failures.append(f"{name}: {error}")
    return result, CalibrationFiles(result_path, infos, tuple(exported), tuple(failures))


@dataclass(frozen=True, eq=False)
class Refinement:
    """What a /refine did.

    Attributes:
        result: the calibration with the moved cameras re-estimated (None: no camera moved).
        moved: the cameras judged moved, by name.
        lines: the judgement, one line per moved camera (``cam1 moved: residual 6.1 px, was 0.4``).
        frames: new frames used (those after the move).
        files: where the repaired calibration was written (None: nothing written).
        after: the views after the move (what the repair's report shows; None: no camera moved).
    """

    result: CalibrationResult | None
    moved: tuple[str, ...]
    lines: tuple[str, ...]
    frames: int
    files: CalibrationFiles | None
    after: WandObservations | None = None


def refine_calibration(
    rig: RigSpec,
    result: CalibrationResult,
    new: WandObservations,
    output_dir: Path,
    *,
    intrinsics: bool = False,
) -> Refinement:
    """Judge from the views ``new`` (taken after ``result``'s calibration, in time order) which cameras
    moved, re-estimate only those from the views after the move (their intrinsics too if asked), and
    write the result files as :func:`run_calibration` does (a report would be of the views after the move).

    Raises:
        InsufficientDataError: too few views after the move tie a moved camera to two unmoved ones.
        OutputError: the result files cannot be written.
    """
    names = rig.camera_names
    models = tuple(result.camera(n).model for n in names)
    poses = tuple(result.camera(n).pose for n in names)
    moved, lines = judge_moved(names, models, poses, rig.wand, result.sigma_px, new.uv)
    if not moved:
        return Refinement(None, (), (), 0, None)
    first, fixed = repair_moved(
        models, poses, rig.wand, result.sigma_px, new.uv, moved, intrinsics=intrinsics, names=names
    )
    after = new.select_frames(np.arange(first, new.frames.size))
    note = (
        f"{', '.join(names[c] for c in moved)} re-estimated by /refine from frames {int(new.frames[first])}.."
        f"{int(new.frames[-1])} ({fixed.placements} placements; every other camera as calibrated)"
    )
    repaired = repaired_result(result, fixed, names, note)
    repaired = replace(repaired, quality=judge(repaired, noise_wand_error(repaired, names, after.uv)))
    result_path = output_dir / "result.yaml"
    check_writable(calibration_paths(names, result_path, output_dir / "camera_info"))
    infos = tuple(write_calibration(repaired, result_path, output_dir / "camera_info")[1:])
    files = CalibrationFiles(result_path, infos)
    return Refinement(repaired, tuple(names[c] for c in moved), tuple(lines), int(after.frames.size), files, after)


def summary(result: CalibrationResult, files: CalibrationFiles) -> str:
    """One line for a service answer: per camera RMS, wand-length RMS, estimated time offsets, where the result is."""
    cameras = ", ".join(f"{c.name} {c.rms_reprojection_px:.2f} px" for c in result.cameras)
    timing = ""
    if result.timing is not None and result.timing.time_offsets == "estimated":
        scale, unit = (1000.0, "ms") if result.timing.unit == "s" else (1.0, "frames")
        offsets = ", ".join(f"{c.name} {scale * c.time_offset:+.2f}" for c in result.cameras)
        timing = f"; time offsets ({unit}, reference {result.reference_camera}) {offsets}"
    failed = "".join(f"; export {failure}" for failure in files.export_failures)
    quality = "" if result.quality is None else f"; {result.quality.line()}"
    return f"RMS {cameras}; wand {result.wand_length_rms_mm:.2f} mm RMS{timing}{quality}; {files.result}{failed}"
