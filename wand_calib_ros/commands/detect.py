"""``wand-calib detect``: the wand found in a rosbag2 of camera images, or in one video file (or folder of numbered
images) per camera, written as an observations CSV."""

from __future__ import annotations

import argparse
import logging
import os
import sys
import time
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING

from wand_calib_ros.errors import WandCalibError
from wand_calib_ros.io.outputs import check_writable, is_special, write_text

if TYPE_CHECKING:
    from wand_calib_ros.core.model.rig import RigSpec
    from wand_calib_ros.detection.blobs import Blobs
    from wand_calib_ros.detection.wand import WandDetection
    from wand_calib_ros.io.bags import ImageFrame
    from wand_calib_ros.io.videos import CameraSource

log = logging.getLogger("wand_calib_ros")

HELP = "detect the wand in a rosbag2 of camera images, or in one video per camera"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The command's arguments."""
    parser.add_argument("bag", type=Path, nargs="?", help="rosbag2 directory (mcap or sqlite3), or --video instead")
    parser.add_argument(
        "--video",
        action="append",
        default=[],
        metavar="CAM=PATH",
        help="a camera's video file (mp4, mov, avi, mkv: what OpenCV's FFmpeg reads) or folder of numbered images; "
        "once per camera, instead of a bag (the videos may start seconds apart: calibrate lines them up)",
    )
    parser.add_argument("--fps", type=float, help="the frame rate of folders of images (videos have their own)")
    parser.add_argument("--cameras", required=True, type=Path, help="rig description (cameras.yaml)")
    parser.add_argument("--output", required=True, type=Path, help="observations CSV to write")
    topic_arguments(parser)
    parser.add_argument(
        "--sync-tolerance-ms",
        type=float,
        default=0.0,
        help="images further apart never form a frame (default 0: half the frame period)",
    )
    parser.add_argument("--debug-dir", type=Path, help="write overlay images (blobs, chosen A/B/C) here")
    parser.add_argument("--debug-every", type=int, default=30, help="overlay every N-th image per camera (default 30)")


def topic_arguments(parser: argparse.ArgumentParser) -> None:
    """``--topic`` and ``--transport``: where a bag holds each camera's images (``detect``, ``mask``)."""
    parser.add_argument(
        "--topic",
        help="topic pattern, e.g. /{camera}/image_raw (default: each camera's image_topic in the rig file, "
        "else /<camera>/image_raw)",
    )
    parser.add_argument(
        "--transport",
        choices=("auto", "raw", "compressed"),
        default="auto",
        help="raw images, image_transport's <topic>/compressed, or auto (default): raw where the bag has it",
    )


def camera_topics(args: argparse.Namespace, rig: RigSpec) -> dict[str, str]:
    """Per camera the bag's topic to read: ``--topic`` or the rig file's ``image_topic``, raw or compressed
    (``--transport``)."""
    from wand_calib_ros.io.bags import bag_topics, choose_topics
    from wand_calib_ros.io.rig_yaml import load_camera_endpoints

    if args.topic is None:
        raw = {name: endpoint.image_topic for name, endpoint in load_camera_endpoints(args.cameras).items()}
    else:
        raw = _image_topics(args.topic, rig.camera_names)
    return choose_topics(bag_topics(args.bag), raw, args.transport)


def _image_topics(pattern: str, names: tuple[str, ...]) -> dict[str, str]:
    """Each camera's image topic from ``--topic`` (``{camera}`` is the camera's name)."""
    try:
        topics = {name: pattern.format(camera=name) for name in names}
    except (KeyError, IndexError) as error:
        raise WandCalibError(
            f"--topic {pattern!r}: {{{error.args[0]}}} is not a field; the only one is {{camera}} "
            "(e.g. /{camera}/image_raw)"
        ) from None
    except ValueError as error:
        raise WandCalibError(f"--topic {pattern!r}: {error} (the field is {{camera}}; {{{{ is a brace)") from None
    if len(set(topics.values())) < len(topics):
        raise WandCalibError(
            f"--topic {pattern!r} gives every camera the same topic {topics[names[0]]}: put {{camera}} in it, "
            "or one camera's images would be written as another's"
        )
    return topics


def video_sources(args: argparse.Namespace, rig: RigSpec) -> dict[str, CameraSource]:
    """Each camera's ``--video CAM=PATH``, checked: every camera of the rig once, no other, each file readable and
    of its camera's size (``--fps`` for folders of images)."""
    from wand_calib_ros.io.videos import CameraSource, check_sources

    if args.bag is not None:
        raise WandCalibError(f"give a bag ({args.bag}) or --video files, not both")
    if args.fps is not None and not 0 < args.fps <= 1000:
        raise WandCalibError(f"--fps must be a frame rate in Hz (0 < fps <= 1000), got {args.fps:g}")
    sources: dict[str, CameraSource] = {}
    for given in args.video:
        name, sep, path = given.partition("=")
        if not sep or not name or not path:
            raise WandCalibError(f"--video {given!r}: write CAMERA=PATH (e.g. --video cam0=cam0.mp4)")
        if name not in rig.camera_names:
            raise WandCalibError(
                f"--video {given}: no camera '{name}' in {args.cameras} ({', '.join(rig.camera_names)})"
            )
        if name in sources:
            raise WandCalibError(f"--video {given}: camera '{name}' has a video already ({sources[name].path})")
        sources[name] = CameraSource(name, Path(path), args.fps)
    missing = [name for name in rig.camera_names if name not in sources]
    if missing:
        raise WandCalibError(
            f"no --video for {', '.join(missing)}: give every camera of {args.cameras} its video (CAM=PATH)"
        )
    check_sources(sources, {name: rig.camera(name).image_size for name in sources})
    return {name: sources[name] for name in rig.camera_names}


def run(args: argparse.Namespace) -> int:
    import cv2

    from wand_calib_ros.collection.recording import detect_cameras_apart, detect_recording
    from wand_calib_ros.detection.background import BackgroundOptions
    from wand_calib_ros.detection.blobs import BlobOptions
    from wand_calib_ros.detection.consistency import settle_labels
    from wand_calib_ros.detection.health import save_what_cameras_saw
    from wand_calib_ros.detection.masks import mask_of
    from wand_calib_ros.io.bags import count_images, read_image_frames
    from wand_calib_ros.io.observations_csv import write_observations
    from wand_calib_ros.io.rig_yaml import load_camera_masks, load_rig
    from wand_calib_ros.io.videos import VIDEO_MIN_CONTRAST, camera_frames, count_frames

    if args.sync_tolerance_ms < 0 or args.debug_every < 1:
        raise WandCalibError("--sync-tolerance-ms must be 0 or more and --debug-every at least 1")
    cv2.setNumThreads(1)  # per-image work is small: OpenCV's thread pool only adds overhead here
    rig = load_rig(args.cameras)
    masks = {name: mask_of(spec, rig.camera(name).image_size) for name, spec in load_camera_masks(args.cameras).items()}
    check_writable([args.output])  # before reading the bag
    if args.video:
        sources = video_sources(args, rig)
        topics = {name: str(source.path) for name, source in sources.items()}
        expected, source = count_frames(sources), "the videos"
    elif args.bag is None:
        raise WandCalibError("give a bag or --video CAM=PATH for every camera")
    else:
        topics = camera_topics(args, rig)
        expected, source = count_images(args.bag, topics), str(args.bag)
    started = time.perf_counter()
    seen: dict[str, int] = {}
    show_progress = not args.quiet and expected > 0

    shown = [0]

    def progress(total: int) -> None:
        if show_progress and (total >= shown[0] + 100 or (total == expected and shown[0] < total)):
            shown[0] = total
            done = min(total / expected, 1.0)
            rate = total / max(time.perf_counter() - started, 1e-9)
            bar = "#" * round(30 * done) + "-" * (30 - round(30 * done))
            end = "\n" if total >= expected else ""
            print(f"\rdetect [{bar}] {total}/{expected} images, {rate:.0f}/s", end=end, file=sys.stderr, flush=True)

    def inspect(frame: ImageFrame, blobs: Blobs | None, detection: WandDetection | None, reason: str | None) -> None:
        count = seen[frame.camera] = seen.get(frame.camera, 0) + 1
        if not args.video:  # (videos: their cameras are searched apart, progress counted there)
            progress(sum(seen.values()))
        if args.debug_dir is not None and (count - 1) % max(args.debug_every, 1) == 0:
            from wand_calib_ros.detection.overlay import draw_overlay

            picture = draw_overlay(frame.image, frame.encoding, blobs, detection, reason)
            write_text(
                args.debug_dir / f"{frame.camera}_{frame.stamp_ns}.png", cv2.imencode(".png", picture)[1].tobytes()
            )

    tolerance_ns = int(args.sync_tolerance_ms * 1e6)
    if args.video:  # one file per camera: the cameras searched side by side, a process each on the free cores
        options = BlobOptions(background=BackgroundOptions(min_contrast=VIDEO_MIN_CONTRAST))
        readers = {name: partial(camera_frames, name, source) for name, source in sources.items()}
        workers = min(len(os.sched_getaffinity(0)), len(readers))
        detections = detect_cameras_apart(
            readers, rig, workers=workers, tolerance_ns=tolerance_ns, blob_options=options, inspect=inspect,
            progress=progress, masks=masks,
        )  # fmt: skip
    else:
        frames = read_image_frames(args.bag, topics)
        detections = detect_recording(frames, rig, tolerance_ns=tolerance_ns, inspect=inspect, masks=masks)
    if show_progress and 0 < shown[0] < expected:  # (fewer images than the file said: end the bar's line)
        print(file=sys.stderr)
    observations, _ = settle_labels(rig, detections)
    write_observations(observations, args.output)
    summary = "what each camera saw is not kept beside a terminal or a pipe"
    if not is_special(args.output):  # (nothing is written beside a terminal or a pipe)
        summary = str(save_what_cameras_saw(args.output, detections.reports, detections.masks))
    print(
        f"detected the wand in {source} -> {args.output} ({time.perf_counter() - started:.1f} s); {summary}",
        file=sys.stderr if is_special(args.output) else sys.stdout,
    )
    for name in rig.camera_names:
        report = detections.reports[name]
        where = sys.stderr if is_special(args.output) else sys.stdout
        print(f"  {name}: {report.images} images ({topics[name]}), {report.views} views of the wand", file=where)
        for message in report.messages():
            print(f"    {message}", file=where)
    return 0
