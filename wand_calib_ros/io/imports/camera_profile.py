"""The camera profile of Argus and easyWand: a text file with a row of 12 numbers per camera.

``camera  f  width  height  cx  cy  aspect  r2  r4  t1  t2  r6``, separated by spaces (Argus) or commas: the
camera's number (1-based), its focal length (px), image size (Argus's own profiles write twice the
principal point there), principal point (px, OpenCV's top-left origin and pixel centres), aspect ratio
(fy / fx), and OpenCV's plumb_bob distortion (k1, k2, p1, p2, k3). Lines starting with ``#`` are comments.
Argus's omnidirectional (CMei / ocam) rows, of other lengths, are not read.
"""

from __future__ import annotations

import re
from pathlib import Path

from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.imports.given import GivenIntrinsics
from wand_calib_ros.io.text import finite_number, read_text

#: How far a profile's image size may be from the rig's (Argus writes twice the principal point).
SIZE_TOLERANCE = 0.05
_SEPARATORS = re.compile(r"[\s,;]+")
_COLUMNS = "camera, f, width, height, cx, cy, aspect ratio, r2, r4, t1, t2, r6"


def read_camera_profile(path: str | Path) -> list[GivenIntrinsics]:
    """The cameras of a profile, by camera number (named ``cam<number>``).

    Raises:
        FormatError: naming the file, the row and the problem.
    """
    path = Path(path)
    text = read_text(path, "a camera profile")
    cameras: dict[int, GivenIntrinsics] = {}
    for number, line in enumerate(text.splitlines(), start=1):
        cells = [cell for cell in _SEPARATORS.split(line.strip()) if cell]
        if not cells or cells[0].startswith("#"):
            continue
        if len(cells) != 12:
            raise FormatError(
                path,
                f"{len(cells)} values; a camera profile row has 12 ({_COLUMNS}); omnidirectional (CMei / ocam) "
                "profiles are not supported",
                row=number,
            )
        values = [finite_number(path, number, cell, "a number a profile holds") for cell in cells]
        camera, focal, width, height, cx, cy, aspect = values[:7]
        if camera != int(camera) or camera < 1:
            raise FormatError(path, f"the camera number is {cells[0]!r}; cameras count from 1", row=number)
        if int(camera) in cameras:
            raise FormatError(path, f"camera {int(camera)} comes twice", row=number)
        if focal <= 0 or aspect <= 0 or width < 1 or height < 1:
            raise FormatError(path, "the focal length, image size and aspect ratio must be positive", row=number)
        cameras[int(camera)] = GivenIntrinsics(
            f"cam{int(camera)}",
            (round(width), round(height)),
            ((focal, 0.0, cx), (0.0, focal * aspect, cy), (0.0, 0.0, 1.0)),
            tuple(values[7:]),
            "plumb_bob",
            SIZE_TOLERANCE,
        )
    if not cameras:
        raise FormatError(path, f"no camera rows ({_COLUMNS})")
    return [cameras[key] for key in sorted(cameras)]
