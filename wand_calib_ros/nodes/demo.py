"""The live demo: a rendered mixed-rig recording replayed through the nodes, /calibrate, result vs truth.

1. Render (seeded) a wand waved in front of a 185-degree fisheye and a 4.2 mm
   conventional camera into an mcap bag, with the rig description and the truth
   (``wand-calib render mixed``); an existing rendering is reused.
2. Start ``collector`` (with its calibrator) as its own process on a private
   ROS_DOMAIN_ID, and play the bag into it with ``wand-calib-replay``.
3. Call ``/calibrate`` from a separate ``wand-calib-trigger`` process.
4. Print the answer and the result against the truth, then stop the collector with
   SIGINT (it flushes its buffer and exits 0).

``python -m wand_calib_ros.nodes.demo --out demo_output/live``
"""

from __future__ import annotations

import argparse
import logging
import shutil
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from wand_calib_ros import cli
from wand_calib_ros.errors import WandCalibError
from wand_calib_ros.io.result_yaml import read_result
from wand_calib_ros.io.rig_yaml import load_rig
from wand_calib_ros.nodes.launch import child_env, free_domain_id, start, stop
from wand_calib_ros.sim.truth import compare_with_truth

log = logging.getLogger("wand_calib_ros.demo")


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="wand-calib-demo", description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("demo_output/live"), help="working directory")
    parser.add_argument("--scenario", default="mixed", help="rig to render (default mixed)")
    parser.add_argument("--frames", type=int, default=900, help="frames per camera (30 fps)")
    parser.add_argument("--seed", type=int, default=3, help="rendering seed")
    parser.add_argument("--rate", type=float, default=3.0, help="playback speed over real time")
    return parser


def run_demo(out: Path, scenario: str, frames: int, seed: int, rate: float) -> int:
    """Steps 1-4 of the module docstring; returns the exit code (0: calibrated and stopped cleanly)."""
    if not (out / "bag").exists():
        cli.main(["render", scenario, "--out", str(out), "--frames", str(frames), "--seed", str(seed)])
    output = out / "collector_output"
    shutil.rmtree(output, ignore_errors=True)  # a fresh buffer each run
    domain_id = free_domain_id()
    params = {"cameras_file": str(out / "cameras.yaml"), "output_dir": str(output), "image_qos": "reliable"}
    print(f"collector: ROS_DOMAIN_ID={domain_id}, log {out / 'collector.log'}")
    collector = start("wand_calib_ros.nodes.collector", params, domain_id=domain_id, log=out / "collector.log")
    try:
        started = time.monotonic()
        replay: dict[str, str | float] = {"bag": str(out / "bag"), "cameras_file": params["cameras_file"], "rate": rate}
        played = start("wand_calib_ros.nodes.replay", replay, domain_id=domain_id, log=out / "replay.log").wait()
        print(f"replayed {out / 'bag'} at {rate:g}x in {time.monotonic() - started:.1f} s (exit {played})")
        answer = subprocess.run(
            [sys.executable, "-m", "wand_calib_ros.nodes.trigger", "/calibrate", "--timeout", "300"],
            env=child_env(domain_id),
            capture_output=True,
            text=True,
            check=False,
        )
        print(answer.stdout.strip() or answer.stderr.strip())
        if answer.returncode != 0:
            return 1
        reference, cameras = read_result(output / "result.yaml")
        rig = load_rig(out / "cameras.yaml")
        print("\n".join(compare_with_truth(reference, cameras, rig.wand, out / "truth.yaml")))
        print(f"report: {output / 'report' / 'index.html'}")
    finally:
        code = stop(collector)
        print(f"collector stopped with exit code {code}")
    return 0 if code == 0 else 1


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m wand_calib_ros.nodes.demo``."""
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    args = _parser().parse_args(argv)
    try:
        return run_demo(args.out, args.scenario, args.frames, args.seed, args.rate)
    except WandCalibError as error:
        print(f"demo: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
