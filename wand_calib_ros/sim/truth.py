"""Judging a calibration against the truth a simulation or rendering wrote (``truth.yaml``)."""

from __future__ import annotations

from pathlib import Path

from wand_calib_ros.core.judge.metrics import camera_errors, heldout_wand_rms, rereference
from wand_calib_ros.core.model.rig import WandSpec
from wand_calib_ros.io.observations_csv import read_observations
from wand_calib_ros.io.result_yaml import CameraGeometry, read_result


def compare_with_truth(
    reference: str, cameras: dict[str, CameraGeometry], wand: WandSpec, truth_path: Path, unit: str = "frames"
) -> list[str]:
    """Lines of per camera errors against ``truth_path`` (and D_RMS when ``heldout.csv`` lies next to it).

    Args:
        reference: the calibration's reference camera.
        cameras: its per camera model and pose (X_cam = R X_ref + T, mm).
        wand: the wand lengths.
        truth_path: a ``truth.yaml`` written by ``wand-calib simulate`` or ``render``.
        unit: the calibration's time unit; in seconds, time offsets (relative to ``reference``) and
            readout times are compared with the truth's too.
    """
    _, truth = read_result(truth_path)
    true_poses = rereference({name: g.pose for name, g in truth.items()}, reference)
    lines = [f"against the truth in {truth_path}:"]
    for name, camera in cameras.items():
        if name not in truth:
            continue
        e = camera_errors(camera.model, camera.pose, truth[name].model, true_poses[name])
        extrinsic = f", E_r {e.rotation_deg:.4f} deg, E_t {e.translation:.5f}" if name != reference else ""
        if unit == "s" and reference in truth:
            offset = camera.time_offset - (truth[name].time_offset - truth[reference].time_offset)
            extrinsic += (
                f", time offset error {1000 * offset:+.3f} ms, readout error "
                f"{1000 * (camera.readout - truth[name].readout):+.3f} ms"
            )
        lines.append(
            f"  {name}: focal error {e.focal_mm * 1000:.2f} um ({e.focal_px:.3f} px), "
            f"principal point error {e.principal_point_px:.3f} px{extrinsic}"
        )
    heldout = truth_path.parent / "heldout.csv"
    if heldout.exists():
        names = tuple(cameras)
        obs = read_observations(heldout, names, labels=wand.labels)
        rms = heldout_wand_rms(
            tuple(cameras[n].model for n in names), tuple(cameras[n].pose for n in names), obs.uv, wand
        )
        lines.append(f"  held-out wand length error D_RMS {rms:.3f} mm over {obs.uv.shape[0]} placements ({heldout})")
    return lines
