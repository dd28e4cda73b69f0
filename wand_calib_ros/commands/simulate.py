"""``wand-calib simulate``: a synthetic rig with known truth (cameras.yaml, observations, truth)."""

from __future__ import annotations

import argparse
import dataclasses
import logging
from pathlib import Path

import numpy as np

from wand_calib_ros.commands.takes import take_arguments, take_options, wand_positions
from wand_calib_ros.errors import WandCalibError
from wand_calib_ros.io.observations_csv import write_observations
from wand_calib_ros.sim.outliers import corrupt
from wand_calib_ros.sim.scenarios import SCENARIOS, image_placements, sample_placements, simulate

log = logging.getLogger("wand_calib_ros")

#: Placements in the held-out file written by ``simulate`` (judges D_RMS).
HELDOUT_PLACEMENTS = 100

HELP = "write a synthetic rig with known truth"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The command's arguments."""
    parser.add_argument("scenario", choices=sorted(SCENARIOS), help="rig to simulate")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument("--noise", type=float, default=1.0, help="pixel noise standard deviation (default 1.0)")
    parser.add_argument("--out", required=True, type=Path, help="directory to write into")
    parser.add_argument("--placements", type=int, help="number of wand placements (scenario default if omitted)")
    parser.add_argument(
        "--outliers",
        type=float,
        default=0.0,
        help="fraction of complete camera views to corrupt (A/C swap, spurious blob, 20 px error)",
    )
    parser.add_argument(
        "--wand-mm",
        metavar="POSITIONS",
        help="another wand: its markers' positions along it in mm, comma-separated from 0 (e.g. 0,120,250,400,600)",
    )
    parser.add_argument(
        "--led-cone-deg",
        type=float,
        metavar="DEG",
        help="half-angle of the LEDs' emission cone (scenario default if omitted; 180: seen from everywhere)",
    )
    parser.add_argument(
        "--plumb-bob",
        action="store_true",
        help="conventional, mixed, mixed3: the conventional cameras' true lenses are plumb_bob ones (tangential terms)",
    )
    parser.add_argument(
        "--known-intrinsics",
        action="store_true",
        help="write every camera's true intrinsics into cameras.yaml (intrinsics, fixed: true), as a board gives them",
    )
    parser.add_argument("--true-focal", type=float, help="paper scenario: true focal length in mm (default 2.0)")
    parser.add_argument(
        "--principal-point",
        type=float,
        nargs=2,
        metavar=("U0", "V0"),
        help="paper scenario: true principal point in px (default 310 250)",
    )
    parser.add_argument(
        "--take",
        type=float,
        metavar="SECONDS",
        help="a continuous wave of this length instead of independent placements",
    )
    take_arguments(parser, "for --take")


def run(args: argparse.Namespace) -> int:
    from wand_calib_ros.io.result_yaml import camera_entry, write_yaml
    from wand_calib_ros.io.rig_yaml import save_rig
    from wand_calib_ros.sim.clocks import film, observe, take_trajectory, truth_timing

    factory = SCENARIOS[args.scenario]
    kwargs: dict[str, object] = {}
    if args.true_focal is not None or args.principal_point is not None:
        if args.scenario != "paper":
            raise WandCalibError("--true-focal and --principal-point apply to the 'paper' scenario only")
        if args.true_focal is not None:
            kwargs["true_focal_mm"] = args.true_focal
        if args.principal_point is not None:
            kwargs["principal_point"] = tuple(args.principal_point)
    if args.placements is not None:
        if args.placements < 1:
            raise WandCalibError("--placements must be positive")
        kwargs["n_placements"] = args.placements
    if args.plumb_bob:
        if args.scenario not in ("conventional", "mixed", "mixed3"):
            raise WandCalibError("--plumb-bob applies to the conventional, mixed and mixed3 scenarios")
        kwargs["pinhole"] = True
    if not (args.noise >= 0):
        raise WandCalibError("--noise must be >= 0")
    if not (0 <= args.outliers < 1):
        raise WandCalibError("--outliers must be a fraction in [0, 1)")
    scenario = factory(**kwargs)
    if args.wand_mm is not None:
        scenario = dataclasses.replace(scenario, wand=wand_positions(args.wand_mm))
    if args.led_cone_deg is not None:
        if not 0 < args.led_cone_deg <= 180:
            raise WandCalibError(f"--led-cone-deg must be in (0, 180], got {args.led_cone_deg:g}")
        scenario = dataclasses.replace(scenario, led_cone_deg=args.led_cone_deg)
    rng = np.random.default_rng(args.seed)
    timing: dict[str, dict[str, float]] = {}
    if args.take is not None:
        if not args.take > 0:
            raise WandCalibError("--take must be a positive number of seconds")
        take = take_options(args, args.take)
        clocks = take.clocks(len(scenario.cameras), rng)
        trajectory = take_trajectory(scenario, take, rng)
        observations = observe(
            scenario.rig.camera_names, film(scenario, trajectory, clocks, take.duration_s, rng), args.noise, rng
        )
        timing = truth_timing(scenario.rig.camera_names, clocks)
    else:
        observations = simulate(scenario, args.noise, rng).observations
    if args.outliers > 0:
        sizes = tuple(c.spec.image_size for c in scenario.cameras)
        observations = corrupt(observations, args.outliers, sizes, rng).observations
    heldout = image_placements(
        scenario, *sample_placements(scenario, HELDOUT_PLACEMENTS, rng), args.noise, rng, first_frame=1_000_000
    )
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    rig = scenario.rig
    if args.known_intrinsics:
        cameras = zip(rig.cameras, scenario.cameras, strict=True)
        rig = dataclasses.replace(rig, cameras=tuple(dataclasses.replace(s, intrinsics=c.model) for s, c in cameras))
    save_rig(rig, out / "cameras.yaml")
    write_observations(observations, out / "observations.csv")
    write_observations(heldout.observations, out / "heldout.csv")
    truth = {
        "reference_camera": scenario.cameras[0].spec.name,
        "scenario": scenario.name,
        "seed": args.seed,
        "noise_px": float(args.noise),
        "outlier_fraction": float(args.outliers),
        "cameras": {c.spec.name: camera_entry(c.model, c.pose) | timing.get(c.spec.name, {}) for c in scenario.cameras},
    }
    write_yaml(truth, out / "truth.yaml")
    print(
        f"simulated '{scenario.name}': {len(scenario.cameras)} cameras, {observations.uv.shape[0]} frames, "
        f"noise {args.noise} px -> {out}/cameras.yaml, observations.csv, heldout.csv, truth.yaml"
    )
    return 0
