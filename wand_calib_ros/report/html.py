"""The calibration report: one self-contained HTML page (PNG figures embedded) plus the PNG files."""

from __future__ import annotations

import base64
import contextlib
import gc
import html
import io
import logging
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import matplotlib.pyplot as plt
import numpy as np

from wand_calib_ros.core.model.camera_model import EQUIDISTANT, PLUMB_BOB, RATIONAL_POLYNOMIAL, to_opencv
from wand_calib_ros.core.model.rig import RigSpec, WandObservations
from wand_calib_ros.io.detection_summary import REASON_TEXT, read_summary, summary_path
from wand_calib_ros.io.errors import OutputError
from wand_calib_ros.io.outputs import write_together
from wand_calib_ros.report.analysis import ReportData, prepare
from wand_calib_ros.report.figures import FIGURES

log = logging.getLogger(__name__)

_CAPTIONS = {
    "residual_histograms": "Reprojection residuals per camera (2D norm) of the points the calibration uses; "
    "the points of views beyond its outlier gate (5 sigma), which it does not use, are counted above each "
    "histogram, not drawn. The parameter table's RMS is per image coordinate (the 2D RMS over the square "
    "root of 2).",
    "residual_vectors": "Residual vectors over each image, magnified: a pattern (not noise) means a model or "
    "timing error. Points of views beyond the outlier gate are marked x.",
    "coverage": "Where the wand was seen: image area and off-axis angle. The distortion is only known where data are.",
    "distortion": "Fitted r(theta) with its 2-sigma band against the five classic projections at the nominal focal "
    "length, drawn up to the image's reach (dotted: its corner); below, the 1-sigma uncertainty of the image "
    "radius (shaded: angles never observed).",
    "wand_lengths": "Wand length |AC| of every placement triangulated linearly with the calibration.",
    "rig_3d": "Camera frustums and wand placements in the reference camera's frame.",
    "vision_graph": "Placements shared by camera pairs (M_ij) and the pairs used to chain the initial poses.",
    "running_estimate": "The live session's running estimate, round by round: each camera's image error and "
    "parameter uncertainties and the wand error, as they fell while the wand was waved. Dashed lines: a camera "
    "judged moved (red), a calibration (green), a repair (purple).",
    "timing": "Residual along each point's image motion against its image speed: grey as if the cameras had "
    "seen each frame at one instant, blue with the result's time offsets and readout times. A slope in grey "
    "is a camera out of step; blue should be flat.",
}

_STYLE = """
body { font-family: sans-serif; max-width: 1200px; margin: 2em auto; color: #222; }
table { border-collapse: collapse; font-size: 0.85em; }
td, th { border: 1px solid #ccc; padding: 3px 6px; text-align: right; }
th { background: #eee; }
.warn { color: #a40; }
img { max-width: 100%; }
"""


#: OpenCV's names of each model's distortion coefficients D (ROS camera_info).
_DISTORTION_NAMES = {
    EQUIDISTANT: ("k1", "k2", "k3", "k4"),
    PLUMB_BOB: ("k1", "k2", "p1", "p2", "k3"),
    RATIONAL_POLYNOMIAL: ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"),
}
#: What OpenCV and ROS call each model.
_MODEL_TEXT = {
    EQUIDISTANT: "OpenCV fisheye (cv2.fisheye) / ROS equidistant",
    PLUMB_BOB: "OpenCV pinhole (cv2.projectPoints, 5 coefficients) / ROS plumb_bob",
    RATIONAL_POLYNOMIAL: "OpenCV pinhole (cv2.projectPoints, 8 coefficients) / ROS rational_polynomial",
}
#: Pose columns: result key, header (unit), factor from the result's unit.
_POSE_COLUMNS = (
    *((f"r{a}", f"r{a} (deg)", float(np.degrees(1.0))) for a in "xyz"),
    *((f"t{a}", f"t{a} (mm)", 1.0) for a in "xyz"),
)
#: The result's metrics in plain words: key -> (label, unit).
_METRIC_TEXT = {
    "wand_length_rms_mm": ("wand length error, RMS", "mm"),
    "wand_length_mean_mm": ("wand length, mean", "mm"),
    "wand_length_std_mm": ("wand length, standard deviation", "mm"),
    "sigma_px": ("pixel noise estimated from the residuals", "px"),
    "residuals": ("image coordinates fitted", ""),
    "free_parameters": ("parameters estimated (cameras and wand placements)", ""),
    "placements_used": ("wand placements used", ""),
    "placements_rejected": ("wand placements rejected as outliers", ""),
    "iterations": ("solver iterations", ""),
}


def _with_std(value: float, std: float | None, digits: str = ".5g") -> str:
    return f"{value:{digits}}" + ("" if std is None else f" &plusmn; {std:.3g}")


def _parameter_table(data: ReportData) -> str:
    """Per camera its parameters in its own model as OpenCV and ROS name them (fx, fy, cx, cy and D), with
    standard deviations; rotations as rotation vectors in degrees (the camera's rotation from the reference
    camera's frame); RMS per image coordinate of the points the calibration used (the histograms show the
    2D norm)."""
    heads = (
        "camera",
        "model",
        "fx (px)",
        "fy (px)",
        "cx (px)",
        "cy (px)",
        "distortion D",
        *(h for _, h, _ in _POSE_COLUMNS),
        "RMS per coordinate (px)",
        "views",
        "rejected views",
    )
    head = "".join(f"<th>{h}</th>" for h in heads)
    rows = []
    for name, model, pose in zip(data.names, data.models, data.poses, strict=True):
        entry = data.document["cameras"][name]
        std = entry.get("std", {})
        opencv = to_opencv(model)
        fx, fy = (float(v) for v in model.focal_px)
        focal_std = [None if "k1" not in std else float(std["k1"] * m) for m in model.m]
        names = _DISTORTION_NAMES.get(opencv.distortion_model, tuple(f"d{i}" for i in range(opencv.distortion.size)))
        distortion = ", ".join(f"{n} {v:.4g}" for n, v in zip(names, opencv.distortion, strict=False))
        source = {"given": "given, held", "given_start": "given as a start"}.get(str(entry.get("intrinsics")), "")
        model_cell = f"{html.escape(opencv.distortion_model)}" + (f"<br>({source})" if source else "")
        cells = [
            f'<td style="text-align:left">{model_cell}</td>',
            f"<td>{_with_std(fx, focal_std[0])}</td>",
            f"<td>{_with_std(fy, focal_std[1])}</td>",
            f"<td>{_with_std(float(model.principal_point[0]), std.get('u0'))}</td>",
            f"<td>{_with_std(float(model.principal_point[1]), std.get('v0'))}</td>",
            f'<td style="text-align:left">{html.escape(distortion)}</td>',
        ]
        for (key, _, factor), value in zip(_POSE_COLUMNS, [*pose.rotvec, *pose.translation], strict=True):
            cells.append(f"<td>{_with_std(factor * value, None if key not in std else factor * std[key])}</td>")
        rows.append(
            f"<tr><td>{html.escape(name)}</td>{''.join(cells)}<td>{entry.get('rms_reprojection_px', float('nan')):.3f}"
            f"</td><td>{entry.get('n_views', '')}</td><td>{entry.get('rejected_views', '')}</td></tr>"
        )
    return f"<table><tr>{head}</tr>{''.join(rows)}</table>"


def _models_text(data: ReportData) -> str:
    """What each camera's model is exactly, in OpenCV's and ROS's terms (only the models present)."""
    groups: dict[str, list[str]] = {}
    for name, model in zip(data.names, data.models, strict=True):
        groups.setdefault(model.distortion_model, []).append(name)
    parts = [f"{', '.join(names)}: exactly {_MODEL_TEXT.get(kind, kind)}" for kind, names in groups.items()]
    return "Each camera in its own model; " + "; ".join(parts)


def _metrics(data: ReportData) -> str:
    metrics = data.document.get("metrics", {})
    items = []
    for key, value in metrics.items():
        label, unit = _METRIC_TEXT.get(str(key), (str(key).replace("_", " "), ""))
        shown = f"{value:.4g}" if isinstance(value, float) else str(value)
        items.append(f"<li>{html.escape(label)}: {html.escape(shown)}{' ' + unit if unit else ''}</li>")
    return f"<ul>{''.join(items)}</ul>"


def _quality(data: ReportData) -> str:
    """The quality verdict (result.yaml's ``quality`` block), when the result has one."""
    quality = data.document.get("quality")
    if not quality:
        return ""
    limited = "".join(f"<li>{html.escape(str(reason))}</li>" for reason in quality.get("limited_by", []))
    return (
        f"<h2>Quality: {html.escape(str(quality['grade']))}</h2><p>world error {quality['world_error_mm']:.3g} mm "
        f"(what the pixel noise alone causes: {quality['world_noise_mm']:.3g} mm); pixel noise "
        f"{quality['noise_px']:.3g} px.</p>" + (f"<p>Limited by:</p><ul>{limited}</ul>" if limited else "")
    )


def _events(data: ReportData) -> str:
    """The live session's events (cameras judged moved, calibrations, repairs), when there were any."""
    if not data.events:
        return ""
    start = data.events[0].time
    rows = "".join(
        f"<tr><td>{e.time - start:.1f}</td><td>{html.escape(e.event)}</td><td>{html.escape(e.camera)}</td>"
        f'<td style="text-align:left">{html.escape(e.message)}</td></tr>'
        for e in data.events
    )
    return (
        "<h2>Session events</h2><table><tr><th>time (s)</th><th>event</th><th>camera</th><th>message</th></tr>"
        f"{rows}</table>"
    )


def _what_cameras_saw(observations_path: Path | None) -> str:
    """The detector's report per camera (``<stem>.detection.yaml`` beside the observations, if the detector
    wrote one) with the masks it ended with."""
    summary = read_summary(observations_path) if observations_path is not None else None
    if not summary or observations_path is None:
        return ""
    keys = (
        ("images", "images"),
        ("views", "views"),
        ("static lights", "static_lights"),
        ("masked %", "masked_fraction"),
        ("LEDs saturated %", "saturated"),
        ("dim views %", "dim"),
        ("streak median (px)", "streak_median_px"),
    )
    head = "".join(f"<th>{html.escape(label)}</th>" for label, _ in keys)
    rows, notes, masks = [], [], []
    for name, entry in summary.items():
        cells = []
        for _, key in keys:
            value = entry.get(key, "")
            if key == "static_lights":
                value = len(value) if isinstance(value, list) else value
            elif key in ("masked_fraction", "saturated", "dim") and isinstance(value, int | float):
                value = f"{100 * value:.1f}"
            elif isinstance(value, float):
                value = f"{value:.3g}"
            cells.append(f"<td>{html.escape(str(value))}</td>")
        no_view = entry.get("no_view", {})
        reasons = (
            ", ".join(f"{REASON_TEXT.get(k, k)} {v}" for k, v in no_view.items()) if isinstance(no_view, dict) else ""
        )
        rows.append(f"<tr><th>{html.escape(name)}</th>{''.join(cells)}<td style=\"text-align:left\">"
                    f"{html.escape(reasons)}</td></tr>")  # fmt: skip
        notes += [f'<li class="warn">{html.escape(str(m))}</li>' for m in entry.get("messages", [])]
        mask_file = entry.get("mask")
        picture = cv2.imread(str(observations_path.parent / mask_file), cv2.IMREAD_GRAYSCALE) if mask_file else None
        if picture is not None:
            scale = 240.0 / max(picture.shape[1], 1)
            small = cv2.resize(picture, (240, max(round(picture.shape[0] * scale), 1)), interpolation=cv2.INTER_AREA)
            ok, png = cv2.imencode(".png", cv2.bitwise_not(small))
            if ok:
                encoded = base64.b64encode(png.tobytes()).decode("ascii")
                masks.append(
                    f'<figure style="display:inline-block"><img alt="{html.escape(name)} mask" '
                    f'src="data:image/png;base64,{encoded}"><figcaption>{html.escape(name)}</figcaption></figure>'
                )
    return (
        "<h2>What each camera saw</h2><p>The LED detector's account of each camera's images (beside the "
        f"observations: {html.escape(summary_path(observations_path).name)}).</p>"
        f"<table><tr><th>camera</th>{head}<th>images without a view</th></tr>{''.join(rows)}</table>"
        + (f"<ul>{''.join(notes)}</ul>" if notes else "")
        + (f"<p>Masks (dark: pixels the detector ignored):</p>{''.join(masks)}" if masks else "")
    )


@contextlib.contextmanager
def _garbage_collection_held() -> Iterator[None]:
    """Python's cyclic garbage collection held off while the figures are drawn, then let run as before.

    matplotlib makes tens of thousands of small objects per figure; each burst set off collections that
    walked the whole heap: 0.15 s of a 1.35 s report measured on a live take, more in a process that holds a
    collector node's session. The closed figures are freed by the next collection.
    """
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


def _figures(data: ReportData, out: Path) -> tuple[dict[Path, str | bytes], list[str]]:
    """Each figure the data has as a PNG file in ``out`` (not yet written) and as the page's section."""
    files: dict[Path, str | bytes] = {}
    sections = []
    for name, make in FIGURES.items():
        if name == "timing" and data.timing is None:
            continue  # nothing to compare: synchronised views
        if name == "running_estimate" and data.estimates is None:
            continue  # not a live session
        figure = make(data)
        buffer = io.BytesIO()
        figure.savefig(buffer, format="png", dpi=80)
        plt.close(figure)
        png = buffer.getvalue()
        files[out / f"{name}.png"] = png
        encoded = base64.b64encode(png).decode("ascii")
        sections.append(
            f"<h2>{name.replace('_', ' ')}</h2><p>{html.escape(_CAPTIONS[name])}</p>"
            f'<img alt="{name}" src="data:image/png;base64,{encoded}">'
        )
    return files, sections


def write_report(
    rig: RigSpec,
    observations: WandObservations,
    result_path: Path,
    out: Path,
    observations_path: Path | None = None,
    document: dict[str, Any] | None = None,
) -> Path:
    """Write ``out/index.html`` (self-contained) and one PNG per figure; returns the HTML path.

    Args:
        observations_path: the observations' CSV: the detector's account beside it (``<stem>.detection.yaml``)
            is shown when there is one.
        document: the result as it was written, when ``result_path`` may since hold another
            (:func:`~wand_calib_ros.report.analysis.prepare`).

    Raises:
        OutputError: ``out`` is a file.
    """
    if out.exists() and not out.is_dir():
        raise OutputError(out, "it is a file; give a folder for the report")
    data = prepare(rig, observations, result_path, document)
    with _garbage_collection_held():
        files, sections = _figures(data, out)
    warnings = data.document.get("warnings", [])
    warning_html = (
        "<ul>" + "".join(f'<li class="warn">{html.escape(w)}</li>' for w in warnings) + "</ul>"
        if warnings
        else "<p>No warnings.</p>"
    )
    conventions = data.document.get("conventions", {})
    page = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>wand_calib_ros calibration report</title>
<style>{_STYLE}</style></head><body>
<h1>Calibration report</h1>
<p>{len(data.names)} cameras, reference camera <b>{html.escape(data.reference)}</b>; result file
{html.escape(str(result_path))}. {html.escape(conventions.get("frames", ""))}.
{html.escape(_models_text(data))}.</p>
<h2>Warnings</h2>{warning_html}
<h2>Parameters (&plusmn; one standard deviation)</h2>{_parameter_table(data)}
<h2>Metrics</h2>{_metrics(data)}
{_quality(data)}{_events(data)}{_what_cameras_saw(observations_path)}
{"".join(sections)}
</body></html>
"""
    path = out / "index.html"
    files[path] = page
    write_together(files)  # all together: a failed report leaves none of them
    log.info("report written to %s", path)
    return path
