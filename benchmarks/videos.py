"""Videos started by hand: detection from one MPEG-4 file per camera against the same take's bag, and the clock
alignment's cost.

Run: .venv/bin/python benchmarks/videos.py [--repeats 3] [--seconds 20]

- ``wand-calib detect`` as a whole process (decoding included) on a rendered take of paper4 (four fisheyes,
  640x480, 30 fps, free-running), once from its bag and once from one video per camera (4 Mbit/s MPEG-4, the
  cameras started 0, 1.3, 2.6 and 3.9 s into the take): images per second, median of ``--repeats``. Target: the
  videos at least as fast as the bag.
- The coarse clock alignment (``align_clocks``) on a 60 s take of paper4 with two cameras 2.3 s and -7 s off,
  median of ``--repeats`` (target <= 0.5 s), and on the same take with the clocks agreeing.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from wand_calib_ros.core.initialise.clock_alignment import align_clocks
from wand_calib_ros.io.bags import write_image_bag
from wand_calib_ros.io.rig_yaml import save_rig
from wand_calib_ros.sim.clocks import TakeOptions, film, observe, take_trajectory
from wand_calib_ros.sim.render import RenderOptions, render_take
from wand_calib_ros.sim.scenarios import SCENARIOS
from wand_calib_ros.sim.videos import write_camera_videos

STARTS = {"cam0": 0.0, "cam1": 1.3, "cam2": 2.6, "cam3": 3.9}


def _detect_rate(command: list[str], images: int, repeats: int) -> float:
    """Images per second of a ``wand-calib detect`` process, median of ``repeats``."""
    seconds = []
    for _ in range(repeats):
        began = time.perf_counter()
        subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
        seconds.append(time.perf_counter() - began)
    return images / statistics.median(seconds)


def _detection(seconds: float, repeats: int) -> None:
    scenario = SCENARIOS["paper4"]()
    rng = np.random.default_rng(1)
    options = TakeOptions(duration_s=seconds)
    takes = film(scenario, take_trajectory(scenario, options, rng), options.clocks(4, rng), seconds, rng)
    recording = render_take(scenario, takes, RenderOptions(), rng)
    first = recording.frames[0][1]
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        save_rig(scenario.rig, folder / "cameras.yaml")
        write_image_bag(folder / "bag", recording.frames, scenario.rig.camera_names)
        cli = [sys.executable, "-m", "wand_calib_ros.cli", "-q", "detect", "--cameras", str(folder / "cameras.yaml")]
        bag = _detect_rate(
            [*cli, str(folder / "bag"), "--output", str(folder / "b.csv")], len(recording.frames), repeats
        )
        print(f"detect, {seconds:g} s of paper4 (4 x 640x480 at 30 fps, {len(recording.frames)} images), median of "
              f"{repeats}, as a whole process: bag {bag:.0f} images/s", flush=True)  # fmt: skip
        for label, starts in (("started together", dict.fromkeys(STARTS, 0.0)), ("started apart", STARTS)):
            kept = [f for f in recording.frames if (f[1] - first) / 1e9 >= starts[f[0]] - 1 / 60]
            write_image_bag(folder / f"{label} bag", kept, scenario.rig.camera_names)
            same = _detect_rate([*cli, str(folder / f"{label} bag"), "--output", str(folder / "b.csv")], len(kept),
                                repeats)  # fmt: skip
            videos = write_camera_videos(recording.frames, folder / label, 30.0, starts)
            given = [f"--video={name}={path}" for name, path in videos.items()]
            rate = _detect_rate([*cli, *given, "--output", str(folder / "v.csv")], len(kept), repeats)
            verdict = "ok" if rate >= same else "slower"
            print(f"  videos {label} ({len(kept)} images): {rate:.0f} images/s against {same:.0f} from a bag of the "
                  f"same images, {rate / same:.2f}x ({verdict})")  # fmt: skip


def _alignment(repeats: int) -> None:
    scenario = SCENARIOS["paper4"]()
    options = TakeOptions(duration_s=60.0)
    for label, ahead in (("two cameras 2.3 s and -7 s off", {1: 2.3, 3: -7.0}), ("clocks agreeing", {})):
        clocks = options.clocks(4, np.random.default_rng(2))
        clocks = tuple(replace(c, latency_s=c.latency_s + ahead.get(k, 0.0)) for k, c in enumerate(clocks))
        takes = film(scenario, take_trajectory(scenario, options, np.random.default_rng(1)), clocks, 60.0,
                     np.random.default_rng(3))  # fmt: skip
        observations = observe(scenario.rig.camera_names, takes, 0.25, np.random.default_rng(4))
        runs = []
        for _ in range(repeats):
            began = time.perf_counter()
            _, found = align_clocks(scenario.rig, observations)
            runs.append(time.perf_counter() - began)
        seconds = statistics.median(runs)
        verdict = "ok" if seconds <= 0.5 else "over"
        print(f"align_clocks, paper4 60 s, {label}: {seconds:.3f} s (target <= 0.5 s: {verdict}); "
              f"moved {int(found.moved.sum())} cameras")  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=20.0)
    args = parser.parse_args()
    _detection(args.seconds, args.repeats)
    _alignment(args.repeats)


if __name__ == "__main__":
    main()
