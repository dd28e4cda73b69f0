"""``wand-calib mask``: each camera's mask taken from a stretch of a bag with the wand out of sight."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from wand_calib_ros.commands.detect import camera_topics, topic_arguments
from wand_calib_ros.errors import WandCalibError

HELP = "take each camera's mask (lamps, windows) from a stretch of a bag with the wand out of sight"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The command's arguments."""
    parser.add_argument("bag", type=Path, help="rosbag2 directory (mcap or sqlite3)")
    parser.add_argument("--cameras", required=True, type=Path, help="rig description (cameras.yaml)")
    parser.add_argument("--out", required=True, type=Path, help="folder for <camera>.png (white: ignored)")
    parser.add_argument("--start", type=float, default=0.0, help="seconds after the bag's first image (default 0)")
    parser.add_argument("--seconds", type=float, default=1.0, help="how long the wand is out of sight (default 1)")
    topic_arguments(parser)


def run(args: argparse.Namespace) -> int:
    from wand_calib_ros.detection.blobs import find_blobs, to_gray
    from wand_calib_ros.detection.errors import ImageError
    from wand_calib_ros.detection.masks import MaskTaker, mask_fraction, write_mask
    from wand_calib_ros.io.bags import read_image_frames
    from wand_calib_ros.io.rig_yaml import load_rig

    if not (args.start >= 0 and args.seconds > 0):
        raise WandCalibError("--start must be 0 or more and --seconds positive")
    rig = load_rig(args.cameras)
    if args.out.exists() and not args.out.is_dir():
        raise WandCalibError(f"--out {args.out}: it is a file; give a folder")
    takers = {spec.name: MaskTaker(spec.image_size) for spec in rig.cameras}
    first: int | None = None
    for frame in read_image_frames(args.bag, camera_topics(args, rig)):
        first = frame.stamp_ns if first is None else first
        offset = (frame.stamp_ns - first) / 1e9
        if offset < args.start:
            continue
        if offset > args.start + args.seconds:
            break
        taker = takers[frame.camera]
        if (frame.image.shape[1], frame.image.shape[0]) != taker.size:
            continue
        try:
            taker.add(find_blobs(to_gray(frame.image, frame.encoding)))
        except ImageError:
            continue
    missing = [name for name, taker in takers.items() if taker.images == 0]
    if len(missing) == len(takers):
        raise WandCalibError(f"{args.bag}: no image between {args.start:g} and {args.start + args.seconds:g} s")
    args.out.mkdir(parents=True, exist_ok=True)
    folder = os.path.relpath(args.out.resolve(), args.cameras.resolve().parent)
    print(f"masks from {args.start:g} to {args.start + args.seconds:g} s of {args.bag}; add to {args.cameras}:")
    for name, taker in takers.items():
        if taker.images == 0:
            print(f"  {name}: no image in that stretch: no mask")
            continue
        mask = taker.mask
        write_mask(args.out / f"{name}.png", mask)
        spots = len(taker.circles) // max(taker.images, 1)
        print(
            f"  {name} ({taker.images} images, about {spots} light{'s' if spots != 1 else ''}, "
            f"{100 * mask_fraction(mask):.2f} % of the image): mask: {folder}/{name}.png"
        )
    return 0
