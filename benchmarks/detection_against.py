"""The detector's speed side by side with an earlier commit's, on the same images: this machine's speed varies by
2x between hours, a ratio measured in alternating runs does not.

Run: .venv/bin/python benchmarks/detection_against.py [--against b48e28d] [--rounds 3]

The four cases of ``benchmarks/detection.py`` (640x480 and 1280x1024 mono8, clean spots and a room's images) are
rendered once; each round then runs the earlier commit's detector and this tree's, one after the other, each in a
process of its own over the same images (a camera's stream through the whole detector, one core, CPU time, after
the same untimed warm-up, as ``benchmarks/detection.py`` measures). The earlier commit is taken from this
repository's history (``git archive``). Prints images/s per case and round, each case's range, and the range of the
rounds' ratios.
Target (issue 53): at least the earlier commit's speed in every case.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from detection import (  # (the cases benchmarks/detection.py renders, and its warm-up)
    SENSOR_WIDTH_MM,
    WARM_UP,
    clean_images,
    room_images,
)

ROOT = Path(__file__).resolve().parent.parent
SIZES = ((640, 480), (1280, 1024))

#: Run in each tree's own process: the images/s of every case (the API both trees share).
RATE = """
import json, sys, time
import cv2, numpy as np
from wand_calib_ros.core.model.rig import CameraSpec
from wand_calib_ros.detection.recording import CameraStream
from wand_calib_ros.detection.wand import WandOptions
cv2.setNumThreads(1)
data = np.load(sys.argv[1])
rates = {}
for case in data.files:
    images = data[case]
    pixel_um = 1000.0 * float(sys.argv[2]) / images.shape[2]  # (benchmarks/detection.py's camera)
    spec = CameraSpec("cam", (images.shape[2], images.shape[1]), (pixel_um, pixel_um), 1.8, 92.5)
    warm = CameraStream(spec, WandOptions())  # (untimed: benchmarks/detection.py's WARM_UP)
    for k, image in enumerate(images[:int(sys.argv[3])]):
        warm.push((k + 1) * 33_333_333, image, "mono8")
    stream = CameraStream(spec, WandOptions())
    stamp, begin = 0, time.process_time()
    for _ in range(4):
        for image in images:
            stamp += 33_333_333
            stream.push(stamp, image, "mono8")
    rates[case] = 4 * len(images) / (time.process_time() - begin)
print(json.dumps(rates))
"""


def _render(path: Path) -> list[str]:
    """The four cases' images into ``path`` (npz), in benchmarks/detection.py's order and draws; their names."""
    rng = np.random.default_rng(0)
    cases: dict[str, np.ndarray] = {}
    for width, height in SIZES:
        for name, make in (("clean", clean_images), ("room", room_images)):
            cases[f"{width}x{height} {name}"] = np.stack(make((width, height), rng))
    np.savez(path, **cases)
    return list(cases)


def _tree(commit: str, folder: Path) -> Path:
    """The package of ``commit`` extracted into ``folder`` (its import path)."""
    folder.mkdir()
    archive = subprocess.run(
        ["git", "-C", str(ROOT), "archive", "--format=tar", commit, "wand_calib_ros"],
        check=True,
        capture_output=True,
    ).stdout
    tar = folder / "tree.tar"
    tar.write_bytes(archive)
    with tarfile.open(tar) as opened:
        opened.extractall(folder, filter="data")
    return folder


def _rates(tree: Path, images: Path) -> dict[str, float]:
    """Images/s per case of the detector at ``tree`` (its own process)."""
    done = subprocess.run(
        [sys.executable, "-c", RATE, str(images), str(SENSOR_WIDTH_MM), str(WARM_UP)],
        check=True,
        capture_output=True,
        text=True,
        cwd=images.parent,
        env={**os.environ, "PYTHONPATH": str(tree)},
    )
    rates: dict[str, float] = json.loads(done.stdout.strip().splitlines()[-1])
    return rates


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--against", default="b48e28d", help="the earlier commit (default b48e28d)")
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch)
        images = folder / "images.npz"
        cases = _render(images)
        earlier = _tree(args.against, folder / "earlier")
        runs: dict[str, list[dict[str, float]]] = {"earlier": [], "now": []}
        for round_ in range(args.rounds):
            for label, tree in (("earlier", earlier), ("now", ROOT)):
                runs[label].append(_rates(tree, images))
                rates = " | ".join(f"{case} {runs[label][-1][case]:.0f}" for case in cases)
                print(f"round {round_ + 1} {label:7s} {rates}", flush=True)
    print(f"\nimages/s per core (CPU time), {args.rounds} alternating rounds; this tree against {args.against}:")
    for case in cases:
        now = [run[case] for run in runs["now"]]
        before = [run[case] for run in runs["earlier"]]
        ratios = [a / b for a, b in zip(now, before, strict=True)]  # (each round's pair, run one after the other)
        print(
            f"{case:18s} now {min(now):6.0f}-{max(now):6.0f}  {args.against} {min(before):6.0f}-{max(before):6.0f}"
            f"  ratio {min(ratios):.2f}-{max(ratios):.2f}x"
        )


if __name__ == "__main__":
    main()
