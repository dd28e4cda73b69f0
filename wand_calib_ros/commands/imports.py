"""``wand-calib import``: another tool's wand points read into an observations CSV, and its intrinsics into the rig
file as given intrinsics."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from wand_calib_ros.core.model.rig import RigSpec, WandObservations
from wand_calib_ros.io.observations_csv import write_observations
from wand_calib_ros.io.outputs import check_writable
from wand_calib_ros.io.rig_yaml import load_rig

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
    parser.add_argument("--rig-out", type=Path, help="the rig file with --intrinsics given to its cameras")
    parser.add_argument(
        "--as-start",
        action="store_true",
        help="the intrinsics are a start the calibration refines (fixed: false), not held fixed",
    )
    parser.add_argument(
        "--origin",
        choices=("bottom-left", "top-left"),
        help="the points' pixel origin: bottom-left, y up (Argus, DLTdv: the default of xypts and easyWand 5) or "
        "top-left (OpenCV: the default of caliscope, openlpt and easyWand 6 unless its file says otherwise)",
    )


def run(args: argparse.Namespace) -> int:
    from wand_calib_ros.errors import WandCalibError
    from wand_calib_ros.io.outputs import write_together

    if args.format in INTRINSICS_FORMATS:
        text, summary = _given_rig(args.points, args.cameras, args.out, as_start=args.as_start)
        check_writable([args.out])
        write_together({args.out: text})
        print(f"{summary} -> {args.out}")
        return 0
    if (args.intrinsics is None) != (args.rig_out is None):
        raise WandCalibError("--intrinsics and --rig-out go together: the rig file is written with those intrinsics")
    rig = load_rig(args.cameras)
    observations, note = _points(args, rig)
    given = None
    if args.intrinsics is not None:
        given = _given_rig(args.intrinsics, args.cameras, args.rig_out, as_start=args.as_start)
    check_writable([args.out] + ([args.rig_out] if given is not None else []))  # everything read first
    write_observations(observations, args.out)
    views = int(np.any(np.isfinite(observations.uv), axis=(2, 3)).sum())
    print(f"imported {observations.uv.shape[0]} frames, {views} camera views{note} -> {args.out}")
    if given is not None:
        write_together({args.rig_out: given[0]})
        print(f"{given[1]} -> {args.rig_out}")
    return 0


def _points(args: argparse.Namespace, rig: RigSpec) -> tuple[WandObservations, str]:
    """The observations of ``--points`` in ``--format``, and what else to say of them."""
    if args.format == "xypts":
        from wand_calib_ros.io.imports.xypts import read_xypts

        return read_xypts(args.points, rig, origin=args.origin or "bottom-left"), ""
    if args.format == "easywand":
        from wand_calib_ros.io.imports.easywand import read_easywand

        return read_easywand(args.points, rig, origin=args.origin), ""
    if args.format == "caliscope":
        from wand_calib_ros.io.imports.caliscope import read_caliscope_points as read
    else:
        from wand_calib_ros.io.imports.openlpt import read_openlpt_points as read
    table = read(args.points, rig)
    observations = table.observations
    if args.origin == "bottom-left":
        from wand_calib_ros.io.imports.xypts import from_bottom_left

        observations = observations.with_uv(from_bottom_left(observations.uv, rig))
    ids = ", ".join(f"{i} -> {name}" for i, name in zip(table.camera_ids, rig.camera_names, strict=True))
    skipped = f", {table.skipped} rows its filter set aside left out" if table.skipped else ""
    return observations, f" (camera ids {ids}{skipped})"


def _given_rig(source: Path, cameras: Path, out: Path, *, as_start: bool) -> tuple[str, str]:
    """The rig file ``cameras`` with each camera's intrinsics from ``source`` (matched by name, else by order) as
    text, checked to read as a rig file at ``out``, and what was matched, in words."""
    import yaml

    from wand_calib_ros.io.imports.given import matched, with_given
    from wand_calib_ros.io.imports.intrinsics import read_given
    from wand_calib_ros.io.result_yaml import yaml_text
    from wand_calib_ros.io.rig_yaml import parse_rig
    from wand_calib_ros.io.text import read_yaml

    rig = load_rig(cameras)
    chosen, how = matched(source, rig, read_given(source))
    text = yaml_text(with_given(read_yaml(cameras), chosen, fixed=not as_start))
    parse_rig(yaml.safe_load(text), out)  # what is written is a rig file this package reads where it is written
    pairs = ", ".join(f"{c.name} -> {s.name} ({c.distortion_model})" for c, s in zip(chosen, rig.cameras, strict=True))
    kind = "as a start" if as_start else "held fixed"
    return text, f"imported the intrinsics of {len(chosen)} cameras {how}, {kind}: {pairs}"
