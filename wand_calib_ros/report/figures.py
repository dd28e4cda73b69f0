"""The report's figures (matplotlib, headless): one function per figure, ReportData in, Figure out."""

from __future__ import annotations

import math

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import networkx as nx
import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import LogLocator

from wand_calib_ros.core.initialise.intrinsics_init import PROJECTIONS
from wand_calib_ros.core.model.camera_model import radial_basis, radius_mm
from wand_calib_ros.report.analysis import ReportData


def _margins(figure: Figure, *, top: float = 0.55, bottom: float = 0.55, left: float = 0.7, right: float = 0.25,
             wspace: float = 0.4, hspace: float = 0.55) -> Figure:  # fmt: skip
    """``figure`` with fixed margins (inches: room for titles of one or two lines, tick labels and axis labels)
    and gaps between its axes (fractions of an axis): what tight_layout would find, without its drawing pass (it
    lays out text by drawing every figure once more: a third of the report's time)."""
    width, height = figure.get_size_inches()
    figure.subplots_adjust(left=left / width, right=1 - right / width, bottom=bottom / height, top=1 - top / height,
                           wspace=wspace, hspace=hspace)  # fmt: skip
    return figure


def _grid(n: int, size: float = 3.6) -> tuple[Figure, np.ndarray]:
    cols = min(n, 4)
    rows = math.ceil(n / cols)
    figure, axes = plt.subplots(rows, cols, figsize=(size * cols, size * rows), squeeze=False)
    for axis in axes.ravel()[n:]:
        axis.set_visible(False)
    return figure, axes.ravel()


def residual_histograms(data: ReportData) -> Figure:
    """Per camera histogram of the 2D residual norms of the points the calibration uses; the points of
    rejected views (outliers) are counted, not drawn, so the histogram shows the noise."""
    figure, axes = _grid(len(data.names), size=4.0)
    for axis, name, camera in zip(axes, data.names, data.cameras, strict=False):
        norms = np.linalg.norm(camera.residuals, axis=1)
        finite = np.isfinite(norms)
        used = norms[finite & ~camera.rejected]
        axis.hist(used, bins=40, color="tab:blue")
        rms = float(np.sqrt(np.mean(used**2))) if used.size else float("nan")
        per_coordinate = rms / np.sqrt(2.0)
        outliers = int(np.sum(finite & camera.rejected))
        axis.set_title(
            f"{name}: |residual| (2D) of {used.size} points\nRMS 2D {rms:.2f} px, per coordinate "
            f"{per_coordinate:.2f} px\n{outliers} points of rejected views not shown",
            fontsize=8,
        )
        axis.set_xlabel("px")
        axis.set_ylabel("points")
    return _margins(figure, top=0.75, hspace=0.75)


def residual_vectors(data: ReportData) -> Figure:
    """Per camera residual vectors of the points the calibration uses, drawn at their image positions
    (magnified so the 95th percentile is 5 % of the width); points of rejected views are marked x."""
    figure, axes = _grid(len(data.names), size=4.2)
    for axis, name, camera, spec in zip(axes, data.names, data.cameras, data.rig.cameras, strict=False):
        width, height = spec.image_size
        used = ~camera.rejected & np.all(np.isfinite(camera.residuals), axis=1)
        norms = np.linalg.norm(camera.residuals[used], axis=1)
        scale = 0.05 * width / max(float(np.percentile(norms, 95)) if norms.size else 1.0, 1e-6)
        step = max(1, int(used.sum()) // 1500)
        uv, r = camera.uv[used][::step], camera.residuals[used][::step]
        outliers = camera.uv[camera.rejected]
        if outliers.size:
            axis.plot(outliers[:, 0], outliers[:, 1], "x", color="0.4", markersize=4, label="rejected views")
            axis.legend(fontsize=7, loc="lower right")
        axis.quiver(
            uv[:, 0],
            uv[:, 1],
            r[:, 0] * scale,
            r[:, 1] * scale,
            angles="xy",
            scale_units="xy",
            scale=1,
            width=0.003,
            color="tab:red",
        )
        axis.set_xlim(0, width)
        axis.set_ylim(height, 0)
        axis.set_aspect("equal")
        axis.set_title(f"{name}: residuals x{scale:.0f} (px)", fontsize=9)
    return _margins(figure, top=0.4, hspace=0.35)


def coverage(data: ReportData) -> Figure:
    """Per camera heat map of the observed points over the image and histogram over theta."""
    n = len(data.names)
    figure, axes = plt.subplots(2, n, figsize=(3.6 * n, 6.4), squeeze=False)
    for c, (name, camera, spec) in enumerate(zip(data.names, data.cameras, data.rig.cameras, strict=True)):
        width, height = spec.image_size
        axis = axes[0, c]
        *_, cells = axis.hist2d(
            camera.uv[:, 0],
            camera.uv[:, 1],
            bins=[16, max(4, round(16 * height / width))],
            range=[[0, width], [0, height]],
            cmap="viridis",
        )
        figure.colorbar(cells, ax=axis, shrink=0.8, label="points per cell")
        axis.set_ylim(height, 0)
        axis.set_aspect("equal")
        axis.set_title(f"{name}: image coverage")
        axis = axes[1, c]
        axis.hist(np.degrees(camera.theta), bins=30, range=(0, spec.max_view_angle_deg), color="tab:green")
        axis.set_xlabel("theta (deg)")
        axis.set_ylabel("points")
        axis.set_title(f"{name}: view-angle coverage")
    return _margins(figure, top=0.4, right=0.75, hspace=0.45, wspace=0.45)  # (right: the last colour bar's label)


def distortion_curves(data: ReportData) -> Figure:
    """Per camera fitted r(theta) in px with its 2-sigma band, against the five classic projections."""
    n = len(data.names)
    figure, axes = plt.subplots(2, n, figsize=(3.8 * n, 6.8), squeeze=False)
    for c, (name, model, spec, camera) in enumerate(
        zip(data.names, data.models, data.rig.cameras, data.cameras, strict=True)
    ):
        theta = np.linspace(0.0, spec.max_view_angle, 200)
        scale = float(np.max(model.m))
        fitted = scale * radius_mm(model, theta)
        corner_px = 0.5 * float(np.hypot(*spec.image_size))  # the image's reach from its centre
        top_px = 1.2 * max(corner_px, float(np.nanmax(np.abs(fitted))))
        entry = data.document["cameras"][name]
        covariance = np.array(
            entry.get("radial_covariance", np.diag([entry["std"].get(f"k{i + 1}", 0.0) ** 2 for i in range(5)]))
        )
        powers = np.stack([radial_basis(model, float(t)) for t in theta])  # d r / d k1..k5
        band = 2 * scale * np.sqrt(np.clip(np.einsum("ni,ij,nj->n", powers, covariance, powers), 0, None))
        top, bottom = axes[0, c], axes[1, c]
        for label, function in PROJECTIONS.items():
            with np.errstate(over="ignore", invalid="ignore"):
                curve = scale * function(spec.nominal_focal_mm, theta)
            curve = np.where((curve >= 0) & (curve <= top_px), curve, np.nan)  # beyond the image: not drawn
            top.plot(np.degrees(theta), curve, "--", linewidth=1, label=f"{label} (nominal f)")
        top.plot(np.degrees(theta), fitted, "k", linewidth=2, label="fitted")
        top.fill_between(np.degrees(theta), fitted - band, fitted + band, color="k", alpha=0.2)
        top.axhline(corner_px, color="0.5", linewidth=0.8, linestyle=":", label="image corner")
        top.set_ylim(0, top_px)
        top.set_xlim(0, spec.max_view_angle_deg)
        top.set_title(f"{name}: r(theta)")
        top.set_ylabel("image radius (px)")
        if c == 0:  # (the same lines in every camera's: one legend)
            top.legend(fontsize=6)
        seen = float(np.degrees(np.nanmax(camera.theta))) if camera.theta.size else 0.0
        bottom.plot(np.degrees(theta), band / 2, "k")
        bottom.axvspan(seen, spec.max_view_angle_deg, color="tab:orange", alpha=0.2, label="not observed")
        given = not np.any(band > 0)  # intrinsics given and held: no uncertainty of their own
        bottom.set_title(f"{name}: " + ("r given, held fixed" if given else "1-sigma uncertainty of r"))
        bottom.set_xlabel("theta (deg)")
        bottom.set_ylabel("px")
        if not given:
            bottom.set_yscale("log")
            bottom.yaxis.set_minor_locator(LogLocator(subs=(2.0, 5.0)))  # (the default's eight per decade: 0.06 s)
        if c == 0:
            bottom.legend(fontsize=7)
    return _margins(figure, top=0.4, hspace=0.35, left=0.8)


def wand_lengths(data: ReportData) -> Figure:
    """Histogram of the first-to-last length (|AC| of the three-LED wand) - L of the linearly triangulated
    placements."""
    figure, axis = plt.subplots(figsize=(6, 3.6))
    errors = data.ac_lengths - data.rig.wand.L
    axis.hist(errors, bins=50, color="tab:purple")
    axis.set_title(
        f"{data.rig.wand.ends} - L: mean {np.mean(errors):+.2f} mm, std {np.std(errors):.2f} mm "
        f"({errors.size} placements)"
    )
    axis.set_xlabel("mm")
    return _margins(figure, top=0.4)


def rig_3d(data: ReportData) -> Figure:
    """The cameras (frustums) and the wand placements in the reference frame."""
    figure = plt.figure(figsize=(7, 6))
    axis = figure.add_subplot(projection="3d")
    step = max(1, data.wand_points.shape[0] // 300)
    wands = data.wand_points[::step][:, [0, -1]]  # (W, 2, 3): each wand's ends, drawn as one line broken by NaN
    segments = np.concatenate([wands, np.full((wands.shape[0], 1, 3), np.nan)], axis=1).reshape(-1, 3)
    axis.plot(segments[:, 0], segments[:, 1], segments[:, 2], color="tab:gray", linewidth=0.5)
    extent = float(np.ptp(data.wand_points.reshape(-1, 3), axis=0).max()) if data.wand_points.size else 1000.0
    for name, model, pose, spec in zip(data.names, data.models, data.poses, data.rig.cameras, strict=True):
        centre = pose.center
        width, height = spec.image_size
        corners = np.array([[0, 0], [width, 0], [width, height], [0, height], [0, 0]], dtype=float)
        rays = np.column_stack([(corners - model.principal_point) / model.focal_px, np.ones(5)])
        ends = centre + 0.15 * extent * rays @ pose.rotation  # R^T applied to each ray
        for end in ends[:4]:
            axis.plot(*np.column_stack([centre, end]), color="tab:blue", linewidth=0.8)
        axis.plot(ends[:, 0], ends[:, 1], ends[:, 2], color="tab:blue", linewidth=0.8)
        axis.text(*centre, name, fontsize=8)
    axis.set_xlabel("x (mm)")
    axis.set_ylabel("y (mm)")
    axis.set_zlabel("z (mm)")
    axis.set_title(f"rig in {data.reference}'s frame")
    return _margins(figure, top=0.4, bottom=0.2, left=0.2, right=0.2)


def vision_graph(data: ReportData) -> Figure:
    """Cameras joined by the placements they share (M_ij); the paths used in bold."""
    figure, axis = plt.subplots(figsize=(6, 5.5))
    graph = nx.Graph()
    graph.add_nodes_from(data.names)
    n = len(data.names)
    for i in range(n):
        for j in range(i + 1, n):
            if data.shared[i, j] > 0:
                graph.add_edge(data.names[i], data.names[j], weight=int(data.shared[i, j]))
    layout = nx.circular_layout(graph)
    used = set()
    if data.graph is not None:
        used = {frozenset((data.names[a], data.names[b])) for a, b in data.graph.edges}
    widths = [3.0 if frozenset(e) in used else 0.8 for e in graph.edges]
    colours = ["tab:red" if frozenset(e) in used else "tab:gray" for e in graph.edges]
    nx.draw_networkx(graph, layout, ax=axis, width=widths, edge_color=colours, node_color="tab:cyan", font_size=8)
    nx.draw_networkx_edge_labels(
        graph, layout, edge_labels=nx.get_edge_attributes(graph, "weight"), ax=axis, font_size=7
    )
    axis.set_title(f"vision graph (M_ij; bold: pairs calibrated from {data.reference})")
    axis.axis("off")
    return _margins(figure, top=0.4, bottom=0.1, left=0.1, right=0.1)


def timing(data: ReportData) -> Figure:
    """Per camera residual along the image velocity against the image speed: views taken as
    simultaneous (grey) and carried to their camera's instant with the result's timing (colour)."""
    assert data.timing is not None
    figure, axes = _grid(len(data.names))
    for axis, name, camera in zip(axes, data.names, data.timing, strict=False):
        ok = np.isfinite(camera.speed) & np.isfinite(camera.along_static) & np.isfinite(camera.along_timed)
        step = max(1, int(ok.sum()) // 3000)
        speed = camera.speed[ok][::step]
        axis.scatter(speed, camera.along_static[ok][::step], s=3, color="0.6", label="simultaneous")
        axis.scatter(speed, camera.along_timed[ok][::step], s=3, color="tab:blue", label="with its timing")
        spread = np.percentile(np.abs(camera.along_static[ok]), 99) if ok.any() else 1.0
        axis.set_ylim(-1.2 * spread, 1.2 * spread)
        axis.axhline(0.0, color="k", linewidth=0.5)
        axis.set_title(f"{name}: residual along motion")
        axis.set_xlabel("image speed (px per frame)")
        axis.set_ylabel("residual along the motion (px)")
        axis.legend(loc="upper left", fontsize=7, markerscale=3)
    return _margins(figure, top=0.4, hspace=0.45, left=0.8)


def running_estimate(data: ReportData) -> Figure:
    """The live session's running estimate over time: per camera image error, focal-length and
    principal-point uncertainty, and the wand error; the session's events as vertical lines."""
    history = data.estimates
    assert history is not None
    start = float(history.time.min())
    figure, axes = plt.subplots(1, 4, figsize=(16, 3.6))
    panels = (
        (history.rms_px, "image error (px, per coordinate)"),
        (history.focal_std_percent, "focal length std (%)"),
        (history.principal_std_px, "principal point std (px)"),
    )
    for axis, (values, label) in zip(axes, panels, strict=False):
        for name in data.names:
            mine = np.array([c == name for c in history.camera])
            axis.plot(history.time[mine] - start, values[mine], marker=".", label=name)
        axis.set_ylabel(label)
    first = np.unique(history.time, return_index=True)[1]
    axes[3].plot(history.time[first] - start, history.wand_rms_mm[first], marker=".", color="k")
    axes[3].set_ylabel("wand-length RMS (mm)")
    colours = {"moved": "tab:red", "calibrated": "tab:green", "refined": "tab:purple"}
    for axis in axes:
        axis.set_xlabel("time since the first round (s)")
        for event in data.events:
            axis.axvline(event.time - start, color=colours.get(event.event, "k"), linewidth=0.8, linestyle="--")
    axes[0].legend(fontsize=7)
    return _margins(figure, top=0.2, left=0.85, wspace=0.35)


FIGURES = {
    "residual_histograms": residual_histograms,
    "residual_vectors": residual_vectors,
    "coverage": coverage,
    "distortion": distortion_curves,
    "wand_lengths": wand_lengths,
    "rig_3d": rig_3d,
    "vision_graph": vision_graph,
    "timing": timing,
    "running_estimate": running_estimate,
}
