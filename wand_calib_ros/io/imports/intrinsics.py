"""Which tool's intrinsics file it is: aniposelib's ``calibration.toml`` (:mod:`~wand_calib_ros.io.imports.anipose`),
caliscope's ``camera_array.toml`` (:mod:`~wand_calib_ros.io.imports.caliscope`) or the camera profile of Argus and
easyWand (:mod:`~wand_calib_ros.io.imports.camera_profile`)."""

from __future__ import annotations

from pathlib import Path

from wand_calib_ros.io.imports.anipose import read_anipose, read_toml
from wand_calib_ros.io.imports.caliscope import read_camera_array
from wand_calib_ros.io.imports.camera_profile import read_camera_profile
from wand_calib_ros.io.imports.given import GivenIntrinsics


def read_given(path: str | Path) -> list[GivenIntrinsics]:
    """The cameras of an intrinsics file, whichever tool wrote it: a TOML file with ``[cameras.N]`` tables is
    caliscope's camera array, one with ``[cam_N]`` tables aniposelib's calibration, any other file a camera
    profile (Argus, easyWand).

    Raises:
        FormatError: naming the file and what in it is not as its tool writes it.
    """
    path = Path(path)
    if path.suffix.lower() != ".toml":
        return read_camera_profile(path)
    document = read_toml(path)
    return read_camera_array(path, document) if "cameras" in document else read_anipose(path, document)
