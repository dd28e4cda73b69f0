"""The camera profiles of Argus and easyWand: a text file with a row of numbers per camera.

- 12 numbers (Argus's and easyWand's profile, Argus's ``-clicker-profile.txt``): ``camera  f  width  height
  cx  cy  aspect  r2  r4  t1  t2  r6``: the camera's number (1-based), its focal length (px), image size
  (Argus's own profiles write twice the principal point there), principal point (px), aspect ratio
  (fy / fx), and OpenCV's plumb_bob distortion (k1, k2, p1, p2, k3).
- 17 numbers (Argus's ``-sba-profile.txt``, its wand calibration's cameras, a row per camera in order):
  ``f  cx  cy  aspect  skew  r2  r4  t1  t2  r6  q0 qi qj qk  tx ty tz``; the pose (a quaternion and a
  translation) is not read, and the image size is not written.

Separated by spaces (Argus) or commas; lines starting with ``#`` are comments. The principal point and the
tangential terms are in the pixel frame of the points the profile goes with (Argus's Clicker: bottom left,
y up; :func:`~wand_calib_ros.io.imports.pixels.intrinsics_to_opencv` takes them into OpenCV's). Argus's
per-camera files (10 numbers) and omnidirectional (CMei / ocam) rows are not read.
"""

from __future__ import annotations

import math
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
        if len(cells) not in (12, 17):
            raise FormatError(path, f"{len(cells)} values; {_other_length(len(cells))}", row=number)
        values = [finite_number(path, number, cell, "a number a profile holds") for cell in cells]
        tolerance = SIZE_TOLERANCE
        if len(values) == 17:  # Argus's sba profile: f cx cy AR skew r2 r4 t1 t2 r6 q(4) t(3), a row per camera
            focal, cx, cy, aspect, skew = values[:5]
            if abs(skew) > 1e-9 * abs(focal):
                raise FormatError(
                    path, f"the skew is {skew:g}; a camera with skewed pixels is not supported", row=number
                )
            values = [float(len(cameras) + 1), focal, 2 * cx, 2 * cy, cx, cy, aspect, *values[5:10]]
            tolerance = math.inf  # the size is not written
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
            tolerance,
        )
    if not cameras:
        raise FormatError(path, f"no camera rows ({_COLUMNS})")
    return [cameras[key] for key in sorted(cameras)]


def _other_length(count: int) -> str:
    """What a row of ``count`` values is, and what a profile row has."""
    rows = f"a camera profile row has 12 ({_COLUMNS}) or, in Argus's -sba-profile.txt, 17"
    if count == 10:
        return f"Argus's per-camera profile (-camera-N-profile.txt) holds one camera without its size: {rows}"
    return f"{rows}; omnidirectional (CMei / ocam) profiles are not supported"
