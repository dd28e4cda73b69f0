"""``wand-calib render``: a scenario's waved wand drawn into a rosbag2 of images, with its truth."""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np

from wand_calib_ros.commands.takes import take_arguments, take_options, timed_take, wand_positions
from wand_calib_ros.errors import WandCalibError
from wand_calib_ros.io.observations_csv import write_observations
from wand_calib_ros.sim.room_layout import ROOM_SCENES
from wand_calib_ros.sim.scenarios import SCENARIOS

HELP = "render a scenario's waved wand into a rosbag2 of images"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The command's arguments."""
    parser.add_argument("scenario", choices=sorted(SCENARIOS), help="rig to simulate")
    parser.add_argument(
        "--out", required=True, type=Path, help="directory: bag/ (or bag.bag), cameras.yaml, truth.yaml, drawn.csv"
    )
    parser.add_argument("--frames", type=int, default=300, help="frames per camera (default 300)")
    parser.add_argument("--wand-mm", metavar="POSITIONS", help="another wand (as simulate --wand-mm), e.g. 0,600")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument("--reflections", type=float, default=0.0, help="probability of a spurious spot per image")
    parser.add_argument("--occlusions", type=float, default=0.0, help="probability that an LED is hidden")
    parser.add_argument(
        "--storage",
        choices=("mcap", "sqlite3", "ros1"),
        default="mcap",
        help="bag format (default mcap; ros1: bag.bag)",
    )
    parser.add_argument("--independent", action="store_true", help="independent placements instead of a waved wand")
    parser.add_argument(
        "--room",
        choices=sorted(ROOM_SCENES),
        help="a real room's images instead of clean spots: lamps, windows, LEDs fading with distance and angle, "
        "motion streaks, noise, the scene's exposure and encoding (colour_jpeg: JPEG on <topic>/compressed); "
        "drawn.csv then holds the clearly visible views at mid-exposure",
    )
    take_arguments(
        parser, "with any of them, a take of --frames / fps seconds at --speed through the cameras' shared view"
    )


def run(args: argparse.Namespace) -> int:
    from wand_calib_ros.io.bags import BagFrame, write_image_bag
    from wand_calib_ros.io.result_yaml import camera_entry, write_yaml
    from wand_calib_ros.io.rig_yaml import save_rig
    from wand_calib_ros.sim.clocks import film, take_trajectory, truth_timing
    from wand_calib_ros.sim.render import RenderOptions, render_recording, render_take

    if args.frames < 1:
        raise WandCalibError("--frames must be positive")
    scenario = SCENARIOS[args.scenario]()
    if args.wand_mm is not None:
        scenario = dataclasses.replace(scenario, wand=wand_positions(args.wand_mm))
    rng = np.random.default_rng(args.seed)
    options = RenderOptions(reflection_rate=args.reflections, occlusion_rate=args.occlusions)
    names = scenario.rig.camera_names
    timing: dict[str, dict[str, float]] = {}
    frames: list[BagFrame]
    if args.room is not None:
        if args.independent or args.reflections or args.occlusions:
            raise WandCalibError("--room renders a waved wand in a room: leave out --independent and the spot options")
        from wand_calib_ros.sim.room_take import drawn_observations, room_take

        take = take_options(args, args.frames / min(args.fps))
        clocks = take.clocks(len(names), rng)
        room = room_take(
            scenario, ROOM_SCENES[args.room](), take.duration_s, rng, speed_mm_s=take.speed_mm_s, clocks=clocks
        )
        frames = list(room.frames)
        drawn = drawn_observations(room, names)
        timing = truth_timing(names, clocks) if take.free_running else {}
    elif timed_take(args):
        if args.independent:
            raise WandCalibError("--independent placements have no clocks: leave out the take options")
        take = take_options(args, args.frames / min(args.fps))
        clocks = take.clocks(len(names), rng)
        takes = film(scenario, take_trajectory(scenario, take, rng), clocks, take.duration_s, rng)
        recording = render_take(scenario, takes, options, rng)
        frames, drawn = list(recording.frames), recording.drawn
        timing = truth_timing(names, clocks)
    else:
        fps = take_options(args, 1.0).fps
        assert isinstance(fps, float)
        recording = render_recording(scenario, args.frames, fps, options, rng, independent=args.independent)
        frames, drawn = list(recording.frames), recording.drawn
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    bag = out / ("bag.bag" if args.storage == "ros1" else "bag")
    if bag.exists():
        raise WandCalibError(f"{bag} exists already; choose another --out")
    try:
        write_image_bag(bag, frames, names, storage=args.storage)
    except ValueError as error:
        raise WandCalibError(f"--storage {args.storage}: {error}") from None
    save_rig(scenario.rig, out / "cameras.yaml")
    write_observations(drawn, out / "drawn.csv")
    truth = {
        "reference_camera": names[0],
        "scenario": scenario.name,
        "cameras": {c.spec.name: camera_entry(c.model, c.pose) | timing.get(c.spec.name, {}) for c in scenario.cameras},
    }
    write_yaml(truth, out / "truth.yaml")
    print(f"rendered {len(frames)} images of {len(names)} cameras -> {bag} ({args.storage})")
    return 0
