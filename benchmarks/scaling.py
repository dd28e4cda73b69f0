"""How ``wand-calib calibrate`` scales: cameras x placements -> time and peak memory, and its accuracy.

Run: .venv/bin/python benchmarks/scaling.py [--cases mocap16:2500 mocap16:10000:180 stage64:12500 ...]
     .venv/bin/python benchmarks/scaling.py --cases mocap16:10000 --seeds 1 2 3 --baseline /path/to/checkout

A case is ``scenario:placements[:cone]``; ``cone`` is the LEDs' emission half-angle in degrees
(``simulate --led-cone-deg``; 180: LEDs seen from everywhere, as a motion-capture wand's
diffused LEDs are: on mocap16 every camera then sees most placements, 452k rows for 10,000).

Each case is simulated (``wand-calib simulate``, 1 px noise, the given seeds) into a temporary folder,
then calibrated by ``wand-calib calibrate`` started as a process (CSV reading and process start
included: what a user sees, the package's bytecode compiled as an installation holds it); time and
peak RSS are that process's. The errors against the truth are per camera RMS over the seeds: focal
length (px), principal point (px), rotation E_r (deg) and translation E_t (relative). With
``--baseline`` the same simulated data are calibrated by another checkout of the package too (its
folder holding ``wand_calib_ros/``), and the table gives for every error the worst camera's ratio of
this checkout's RMS to the baseline's, and the ratio over all cameras.

``--repeats N`` calibrates each simulated set N times: the time is the median of every run (this
machine's speed varies by 10-20 % between runs).

Targets on this 2-core machine: 16 cameras x 10,000 placements <= 4 s and <= 600 MB; 64 cameras x
50,000 placements <= 60 s and <= 4 GB; accuracy within 1.05x of the baseline.
"""

from __future__ import annotations

import argparse
import compileall
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from wand_calib_ros.core.judge.metrics import camera_errors, rereference
from wand_calib_ros.io.result_yaml import read_result

DEFAULT_CASES = (
    "mocap16:2500",
    "mocap16:5000",
    "mocap16:10000",
    "mocap16:10000:180",
    "stage64:12500",
    "stage64:25000",
    "stage64:50000",
)
ERRORS = ("focal px", "principal point px", "E_r deg", "E_t")


def calibrate_process(folder: Path, output: Path, package: Path | None) -> tuple[float, float]:
    """Seconds and peak RSS (MB) of one ``wand-calib calibrate`` process (``package``: another checkout)."""
    env = dict(os.environ)
    if package is not None:
        env["PYTHONPATH"] = str(package)
    command = [sys.executable, "-m", "wand_calib_ros.cli", "-q", "calibrate", "--cameras", str(folder / "cameras.yaml")]
    command += ["--observations", str(folder / "observations.csv"), "--output", str(output)]
    began = time.perf_counter()
    child = subprocess.Popen(command, stdout=subprocess.DEVNULL, env=env, cwd=package or None)
    _, status, usage = os.wait4(child.pid, 0)
    seconds = time.perf_counter() - began
    if os.waitstatus_to_exitcode(status):
        raise SystemExit(f"wand-calib calibrate failed on {folder} (exit code {os.waitstatus_to_exitcode(status)})")
    return seconds, usage.ru_maxrss / 1024


def _errors(result: Path, truth: Path) -> dict[str, np.ndarray]:
    """Per camera (sorted by name) errors of a result against the simulation's truth."""
    reference, cameras = read_result(result)
    _, true = read_result(truth)
    true_poses = rereference({n: g.pose for n, g in true.items()}, reference)
    names = sorted(cameras)
    found = [camera_errors(cameras[n].model, cameras[n].pose, true[n].model, true_poses[n]) for n in names]
    return {
        "focal px": np.array([e.focal_px for e in found]),
        "principal point px": np.array([e.principal_point_px for e in found]),
        "E_r deg": np.array([e.rotation_deg for e in found]),
        "E_t": np.array([0.0 if n == reference else e.translation for n, e in zip(names, found, strict=True)]),
    }


def _rms(runs: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    return {key: np.sqrt(np.mean([run[key] ** 2 for run in runs], axis=0)) for key in ERRORS}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", nargs="+", default=list(DEFAULT_CASES), help="scenario:placements")
    parser.add_argument("--seeds", nargs="+", type=int, default=[1])
    parser.add_argument("--baseline", type=Path, help="another checkout to compare the accuracy with")
    parser.add_argument("--repeats", type=int, default=1, help="calibrations of each simulated set (median time)")
    args = parser.parse_args()
    for checkout in (Path(__file__).resolve().parents[1], args.baseline):  # as pip install leaves a package
        if checkout is not None:
            compileall.compile_dir(str(checkout / "wand_calib_ros"), quiet=1)
    print(f"{'case':<18} {'cameras':>7} {'rows':>9} {'time s':>8} {'peak MB':>8}  errors (RMS over seeds {args.seeds})")
    for case in args.cases:
        scenario, placements, *cone = case.split(":")
        times, peaks, mine, theirs, rows, n_cameras = [], [], [], [], 0, 0
        for seed in args.seeds:
            with tempfile.TemporaryDirectory() as tmp:
                folder = Path(tmp)
                command = ["simulate", scenario, "--seed", str(seed), "--noise", "1.0", "--placements", placements]
                command += ["--led-cone-deg", cone[0]] if cone else []
                subprocess.run(
                    [sys.executable, "-m", "wand_calib_ros.cli", "-q", *command, "--out", str(folder)],
                    check=True,
                    stdout=subprocess.DEVNULL,
                )
                rows = sum(1 for _ in (folder / "observations.csv").open()) - 1
                runs = [calibrate_process(folder, folder / "result.yaml", None) for _ in range(args.repeats)]
                times += [seconds for seconds, _ in runs]
                peaks += [peak for _, peak in runs]
                mine.append(_errors(folder / "result.yaml", folder / "truth.yaml"))
                n_cameras = mine[-1]["focal px"].size
                if args.baseline is not None:
                    calibrate_process(folder, folder / "baseline.yaml", args.baseline)
                    theirs.append(_errors(folder / "baseline.yaml", folder / "truth.yaml"))
        ours = _rms(mine)
        errors = ", ".join(f"{key} {np.sqrt(np.mean(ours[key] ** 2)):.4g}" for key in ERRORS)
        print(f"{case:<18} {n_cameras:>7} {rows:>9} {np.median(times):>8.2f} {max(peaks):>8.0f}  {errors}", flush=True)
        if theirs:
            base = _rms(theirs)
            ratios = ", ".join(f"{key} {np.max(ours[key] / np.maximum(base[key], 1e-300)):.3f}x" for key in ERRORS)
            print(f"{'':<18} worst camera against the baseline: {ratios}", flush=True)
            overall = ", ".join(
                f"{key} {np.sqrt(np.mean(ours[key] ** 2) / np.mean(base[key] ** 2)):.3f}x" for key in ERRORS
            )
            print(f"{'':<18} all cameras against the baseline: {overall}", flush=True)


if __name__ == "__main__":
    main()
