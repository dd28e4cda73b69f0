"""``wand-calib import``: another tool's wand points read into an observations CSV, and its intrinsics into the rig
file as given intrinsics."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from wand_calib_ros.core.model.rig import RigSpec, WandObservations
from wand_calib_ros.io.imports.given import GivenIntrinsics
from wand_calib_ros.io.imports.pixels import ARGUS_CLICKER, OPENCV, PixelFrame, WrittenPoints
from wand_calib_ros.io.observations_csv import write_observations
from wand_calib_ros.io.outputs import check_writable

HELP = "read another tool's wand points into an observations CSV (and its intrinsics into the rig file)"

#: The formats of wand points, and those of intrinsics alone (``--points`` is then the intrinsics file).
POINT_FORMATS = ("xypts", "easywand", "caliscope", "openlpt")
INTRINSICS_FORMATS = ("anipose", "argus-profile")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The command's arguments."""
    parser.add_argument(
        "--format",
        required=True,
        choices=POINT_FORMATS + INTRINSICS_FORMATS,
        help="points: xypts (easyWand/Argus/DLTdv *xypts.csv), easywand (easyWand's *_easyWandData.mat or "
        "*_easyWand6Data.mat), caliscope (its point table: sync_index, cam_id, keypoint_id, img_loc_x, img_loc_y), "
        "openlpt (pyOpenLPT's wand points CSV); intrinsics alone: anipose (calibration.toml), argus-profile "
        "(Argus / easyWand camera profile)",
    )
    parser.add_argument("--points", required=True, type=Path, help="the other tool's file (its intrinsics file for "
                        "anipose and argus-profile)")  # fmt: skip
    parser.add_argument("--cameras", required=True, type=Path, help="rig description (camera C = its C-th camera)")
    parser.add_argument(
        "--out", required=True, type=Path, help="observations CSV to write (anipose, argus-profile: the rig file)"
    )
    parser.add_argument(
        "--intrinsics",
        type=Path,
        help="the other tool's intrinsics too: calibration.toml (anipose), camera_array.toml (caliscope) or a camera "
        "profile (Argus, easyWand); written into the rig file --rig-out",
    )
    parser.add_argument(
        "--rig-out",
        type=Path,
        help="the rig file with --intrinsics (or the intrinsics the points file carries: easyWand's) given to its "
        "cameras",
    )
    parser.add_argument(
        "--as-start",
        action="store_true",
        help="the intrinsics are a start the calibration refines (fixed: false), not held fixed",
    )
    parser.add_argument(
        "--origin",
        choices=("bottom-left", "top-left"),
        help="the points' pixel origin where the file does not say it (or to override it): bottom-left, y up (DLTdv "
        "up to 7) or top-left (DLTdv 8); without it the origin is decided from the intrinsics given, or asked for; "
        "argus-profile alone: top-left reads it in OpenCV's frame instead of Argus's Clicker's",
    )


def run(args: argparse.Namespace) -> int:
    from wand_calib_ros.errors import WandCalibError
    from wand_calib_ros.io.imports.intrinsics import read_given
    from wand_calib_ros.io.outputs import write_together
    from wand_calib_ros.io.rig_yaml import load_rig

    if args.format in INTRINSICS_FORMATS:
        rig = load_rig(args.cameras)
        # a profile alone: Argus's Clicker frame unless told top-left (OpenCV's); aniposelib's TOML: OpenCV's
        frame = ARGUS_CLICKER if args.format == "argus-profile" and args.origin != "top-left" else OPENCV
        text, summary, _ = _given_rig(args.points, args.cameras, rig, read_given(args.points), frame, args)
        check_writable([args.out])
        write_together({args.out: text})
        print(f"{summary} -> {args.out}")
        return 0
    if args.intrinsics is not None and args.rig_out is None:
        raise WandCalibError("--intrinsics and --rig-out go together: the rig file is written with those intrinsics")
    rig = load_rig(args.cameras)
    written, note = _points(args, rig)
    given: tuple[Path, list[GivenIntrinsics], bool] | None = None  # the source, its cameras, in the points' frame
    if args.intrinsics is not None:
        given = (args.intrinsics, read_given(args.intrinsics), args.intrinsics.suffix.lower() != ".toml")
    elif written.intrinsics is not None:
        given = (args.points, list(written.intrinsics), True)
    if args.rig_out is not None and given is None:
        raise WandCalibError(
            "--rig-out writes the rig file with intrinsics: give --intrinsics (the points file carries none)"
        )
    frame, why = _origin(args, rig, written, given)
    heights = np.array([spec.image_size[1] for spec in rig.cameras], dtype=np.float64)
    uv = written.uv(heights, frame.origin)
    observations = WandObservations(written.frames, rig.camera_names, uv)
    rig_text = None
    if given is not None and args.rig_out is not None:
        rig_text = _given_rig(given[0], args.cameras, rig, given[1], frame if given[2] else OPENCV, args)
    check_writable([args.out] + ([args.rig_out] if rig_text is not None else []))  # everything read first
    write_observations(observations, args.out)
    views = int(np.any(np.isfinite(observations.uv), axis=(2, 3)).sum())
    print(f"imported {observations.uv.shape[0]} frames, {views} camera views{note} -> {args.out}")
    print(f"pixels: {why}")
    if rig_text is not None:
        write_together({args.rig_out: rig_text[0]})
        print(f"{rig_text[1]} -> {args.rig_out}")
    elif written.intrinsics is not None:
        print(f"{args.points.name} carries the cameras' intrinsics: --rig-out FILE writes them into a rig file")
    return 0


def _points(args: argparse.Namespace, rig: RigSpec) -> tuple[WrittenPoints, str]:
    """The points of ``--points`` in ``--format`` as written, and what else to say of them."""
    if args.format == "xypts":
        from wand_calib_ros.io.imports.xypts import read_xypts

        return read_xypts(args.points, rig), ""
    if args.format == "easywand":
        from wand_calib_ros.io.imports.easywand import read_easywand

        return read_easywand(args.points, rig), ""
    if args.format == "caliscope":
        from wand_calib_ros.io.imports.caliscope import read_caliscope_points as read

        writer = "caliscope's point table"
    else:
        from wand_calib_ros.io.imports.openlpt import read_openlpt_points as read

        writer = "pyOpenLPT's wand points"
    table = read(args.points, rig)
    observations = table.observations
    ids = ", ".join(f"{i} -> {name}" for i, name in zip(table.camera_ids, rig.camera_names, strict=True))
    skipped = f", {table.skipped} rows its own calibration does not use left out" if table.skipped else ""
    alone = f", {table.one_marker_views} views with one marker left out" if table.one_marker_views else ""
    return WrittenPoints(observations.frames, observations.uv, OPENCV, writer), f" (camera ids {ids}{skipped}{alone})"


def _origin(
    args: argparse.Namespace,
    rig: RigSpec,
    written: WrittenPoints,
    given: tuple[Path, list[GivenIntrinsics], bool] | None,
) -> tuple[PixelFrame, str]:
    """The points' pixel frame, its origin known, and why, in words.

    Raises:
        WandCalibError: the file does not say its origin, and neither the user nor the data decide it.
    """
    from wand_calib_ros.errors import WandCalibError

    pixels = written.pixels
    if args.origin is not None or pixels.origin is not None:
        frame = pixels.with_origin(args.origin) if args.origin is not None else pixels
        said = "--origin" if args.origin is not None else "as the file says"
        return frame, (
            f"{written.writer}: origin {frame.origin} ({said}), the first pixel's centre at ({frame.first[0]:g}, "
            f"{frame.first_y():g})"
        )
    ask = (
        f"{args.points}: {written.writer} do not say their pixel origin: give --origin top-left (DLTdv 8, Argus's "
        "exports) or bottom-left (DLTdv up to 7, Argus's y flip)"
    )
    if given is None:
        raise WandCalibError(ask + ", or intrinsics (--intrinsics) to decide it from the fit")
    if given[2]:
        frame = pixels.with_origin("top-left")
        return frame, (
            f"{written.writer} do not say their origin and the intrinsics are in their frame: either origin fits "
            f"alike, one the other's mirror image, so took top-left (DLTdv 8's; --origin bottom-left for DLTdv up "
            f"to 7), {frame.first[0]:g}-based"
        )
    from wand_calib_ros.io.imports.origin import fit_origins

    held = _given_rig(given[0], args.cameras, rig, given[1], OPENCV, args)[2]  # the rig file's own reading of them
    models = [spec.intrinsics for spec in held.cameras if spec.intrinsics is not None]
    fit = fit_origins(written, rig, models)
    if fit.chosen is None:
        raise WandCalibError(f"{ask}; calibrated with {given[0].name} held, both fit alike ({fit.in_words()})")
    frame = pixels.with_origin(fit.chosen)
    return frame, (
        f"{written.writer} do not say their origin: {fit.chosen} calibrates with {given[0].name} held "
        f"({fit.in_words()})"
    )


def _given_rig(
    source: Path, cameras: Path, rig: RigSpec, given: list[GivenIntrinsics], frame: PixelFrame, args: argparse.Namespace
) -> tuple[str, str, RigSpec]:
    """The rig file ``cameras`` with each camera's intrinsics from ``given`` (matched by name, else by order,
    taken from the pixel ``frame`` they are written in) as text, what was matched, in words, and the rig that
    text describes (read as a rig file where it is written)."""
    import yaml

    from wand_calib_ros.io.imports.given import matched, with_given
    from wand_calib_ros.io.imports.pixels import intrinsics_to_opencv
    from wand_calib_ros.io.result_yaml import yaml_text
    from wand_calib_ros.io.rig_yaml import parse_rig
    from wand_calib_ros.io.text import read_yaml

    out = args.out if args.format in INTRINSICS_FORMATS else args.rig_out
    chosen, how = matched(source, rig, given)
    chosen = [
        intrinsics_to_opencv(camera, spec.image_size[1], frame)
        for camera, spec in zip(chosen, rig.cameras, strict=True)
    ]
    text = yaml_text(with_given(read_yaml(cameras), chosen, fixed=not args.as_start))
    held = parse_rig(yaml.safe_load(text), out)  # a rig file this package reads where it is written
    pairs = ", ".join(f"{c.name} -> {s.name} ({c.distortion_model})" for c, s in zip(chosen, rig.cameras, strict=True))
    kind = "as a start" if args.as_start else "held fixed"
    return text, f"imported the intrinsics of {len(chosen)} cameras {how}, {kind}: {pairs}", held
