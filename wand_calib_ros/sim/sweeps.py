"""The paper's simulation sweeps (Figs. 4-6): noise, focal-length offset, principal-point offset.

Each point of a sweep simulates the paper's two- and three-fisheye rigs several
times with fresh noise and placements, calibrates them, and records the errors
against the truth: focal length (k1, mm), principal point (u0, v0, px), E_r
(deg), E_t and the RMS reprojection error (px). Rows go to CSV; the means per
point are plotted like the paper's figures.
"""

from __future__ import annotations

import csv
import logging
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np

from wand_calib_ros.core.judge.metrics import camera_errors
from wand_calib_ros.core.pipeline import calibrate
from wand_calib_ros.errors import WandCalibError
from wand_calib_ros.sim.scenarios import Scenario, paper_fisheye_scenario, simulate

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SweepRow:
    """One camera of one calibration run at one sweep point.

    Attributes:
        sweep: "noise", "focal" or "principal_point".
        n_cameras: 2 or 3.
        value: the swept quantity (noise px; true focal mm; principal-point offset px along u = v).
        run: run index at this point.
        camera: camera name.
        focal_error_mm: |k1 - k1_true|.
        u0_error_px, v0_error_px: principal point errors (absolute).
        rotation_error_deg: E_r (0 for the reference camera).
        translation_error: E_t (NaN for the reference camera).
        rms_px: the camera's RMS reprojection error.
        failure: the error message when the calibration failed, else "".
    """

    sweep: str
    n_cameras: int
    value: float
    run: int
    camera: str
    focal_error_mm: float
    u0_error_px: float
    v0_error_px: float
    rotation_error_deg: float
    translation_error: float
    rms_px: float
    failure: str = ""


@dataclass(frozen=True)
class Sweep:
    """A sweep definition: the swept values and how each makes a scenario and a noise level."""

    name: str
    label: str
    values: tuple[float, ...]
    scenario: Callable[[float, int], Scenario]
    noise: Callable[[float], float]


def _noise_scenario(_: float, n_cameras: int) -> Scenario:
    return paper_fisheye_scenario(n_cameras=n_cameras)


def _focal_scenario(focal: float, n_cameras: int) -> Scenario:
    return paper_fisheye_scenario(n_cameras=n_cameras, true_focal_mm=focal, nominal_focal_mm=2.0)


def _principal_scenario(offset: float, n_cameras: int) -> Scenario:
    return paper_fisheye_scenario(n_cameras=n_cameras, principal_point=(270.0 + offset, 190.0 + offset))


SWEEPS = {
    "noise": Sweep(
        "noise",
        "pixel noise sigma (px)",
        (0.0, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 1.75, 2.0),
        _noise_scenario,
        lambda value: value,
    ),
    "focal": Sweep(
        "focal", "true focal length (mm), nominal 2 mm", (1.5, 1.75, 2.0, 2.25, 2.5), _focal_scenario, lambda _: 1.0
    ),
    "principal_point": Sweep(
        "principal_point",
        "true principal point (270 + x, 190 + x) px",
        (0.0, 25.0, 50.0, 75.0, 100.0),
        _principal_scenario,
        lambda _: 1.0,
    ),
}


def run_sweep(
    sweep: Sweep, n_cameras: int, runs: int, seed: int = 0, values: Sequence[float] | None = None
) -> list[SweepRow]:
    """Calibrate ``runs`` simulations per sweep value; failures are recorded, not raised."""
    rows: list[SweepRow] = []
    for index, value in enumerate(sweep.values if values is None else values):
        scenario = sweep.scenario(value, n_cameras)
        for run in range(runs):
            rng = np.random.default_rng([seed, n_cameras, index, run])
            data = simulate(scenario, sweep.noise(value), rng)
            try:
                result = calibrate(scenario.rig, data.observations)
            except WandCalibError as error:
                log.warning("%s %s cameras value %g run %d failed: %s", sweep.name, n_cameras, value, run, error)
                nan = float("nan")
                rows.extend(
                    SweepRow(sweep.name, n_cameras, value, run, c.spec.name, nan, nan, nan, nan, nan, nan, str(error))
                    for c in scenario.cameras
                )
                continue
            for camera in scenario.cameras:
                mine = result.camera(camera.spec.name)
                e = camera_errors(mine.model, mine.pose, camera.model, camera.pose)
                du, dv = np.abs(mine.model.principal_point - camera.model.principal_point)
                rows.append(
                    SweepRow(
                        sweep.name,
                        n_cameras,
                        value,
                        run,
                        camera.spec.name,
                        e.focal_mm,
                        float(du),
                        float(dv),
                        e.rotation_deg,
                        e.translation,
                        mine.rms_reprojection_px,
                    )
                )
    return rows


METRICS = (
    ("focal_error_mm", "focal length error (mm)"),
    ("u0_error_px", "u0 error (px)"),
    ("v0_error_px", "v0 error (px)"),
    ("rotation_error_deg", "E_r (deg)"),
    ("translation_error", "E_t"),
    ("rms_px", "RMS reprojection error (px)"),
)


def summarise(rows: Iterable[SweepRow]) -> dict[tuple[int, float], dict[str, float]]:
    """Mean of every metric per (n_cameras, value) over runs and cameras (NaN-aware)."""
    grouped: dict[tuple[int, float], list[SweepRow]] = {}
    for row in rows:
        grouped.setdefault((row.n_cameras, row.value), []).append(row)
    out = {}
    for key, members in grouped.items():
        out[key] = {
            name: float(np.nanmean([getattr(r, name) for r in members]))
            if any(np.isfinite(getattr(r, name)) for r in members)
            else float("nan")
            for name, _ in METRICS
        }
        out[key]["failures"] = float(sum(bool(r.failure) for r in members))
    return out


def write_csv(rows: Sequence[SweepRow], path: Path) -> None:
    """All rows, one per camera and run."""
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=[f.name for f in fields(SweepRow)])
        writer.writeheader()
        writer.writerows(asdict(r) for r in rows)


def plot(sweep: Sweep, rows: Sequence[SweepRow], path: Path) -> None:
    """A 2 x 3 figure like the paper's: each metric's mean against the swept value, 2 and 3 cameras."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    summary = summarise(rows)
    figure, axes = plt.subplots(2, 3, figsize=(13, 7))
    for axis, (name, title) in zip(axes.ravel(), METRICS, strict=True):
        for n_cameras in sorted({k[0] for k in summary}):
            values = sorted(v for c, v in summary if c == n_cameras)
            axis.plot(values, [summary[(n_cameras, v)][name] for v in values], "o-", label=f"{n_cameras}cams")
        axis.set_title(title)
        axis.set_xlabel(sweep.label)
        axis.grid(True, alpha=0.3)
        axis.legend()
    figure.suptitle(f"wand_calib_ros: {sweep.name} sweep (mean over runs and cameras)")
    figure.tight_layout()
    figure.savefig(path, dpi=90)
    plt.close(figure)


FIGURES = {"noise": "fig4_noise", "focal": "fig5_focal", "principal_point": "fig6_principal_point"}


def paper_sweeps(out: Path, *, runs: int = 10, seed: int = 0, quick: bool = False) -> list[Path]:
    """Run the three sweeps for 2 and 3 cameras and write ``<figure>.csv`` and ``<figure>.png`` into ``out``.

    Args:
        out: directory to write into.
        runs: simulations per sweep value (the paper used 10).
        seed: base seed.
        quick: only the first, middle and last value of each sweep.
    """
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for name, sweep in SWEEPS.items():
        values = sweep.values[:: max(1, (len(sweep.values) - 1) // 2)] if quick else sweep.values
        rows = [row for n in (2, 3) for row in run_sweep(sweep, n, runs, seed, values)]
        csv_path, png_path = out / f"{FIGURES[name]}.csv", out / f"{FIGURES[name]}.png"
        write_csv(rows, csv_path)
        plot(sweep, rows, png_path)
        written += [csv_path, png_path]
        log.info("wrote %s and %s", csv_path, png_path)
    return written
