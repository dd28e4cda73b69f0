"""aniposelib's ``calibration.toml`` read as given intrinsics (anipose, caliscope and freemocap write it).

One table per camera (``[cam_0]``, ``[cam_1]``, ...; any other table, ``[metadata]``, is not a
camera) with ``name``, ``size`` [width, height], ``matrix`` (K, 3x3), ``distortions`` and, for
aniposelib's FisheyeCamera, ``fisheye = true``: cv2.fisheye's k1..k4 (this package's
``equidistant``); otherwise OpenCV's pinhole coefficients, 4 or 5 (k1, k2, p1, p2[, k3]:
``plumb_bob``) or 8 (``rational_polynomial``). Its ``rotation`` and ``translation`` are the tool's
own calibration of the poses: a wand calibration estimates them again, so they are not read.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.imports.given import GivenIntrinsics
from wand_calib_ros.io.text import read_text


def read_anipose(path: str | Path, document: dict[str, Any] | None = None) -> list[GivenIntrinsics]:
    """The cameras of a ``calibration.toml``, in its tables' order (``cam_0``, ``cam_1``, ... by number).

    Args:
        document: the file already read (:func:`read_toml`), else it is read here.

    Raises:
        FormatError: naming the file, the table and the key at fault.
    """
    path = Path(path)
    document = read_toml(path) if document is None else document
    tables = sorted(
        (key for key, value in document.items() if key.startswith("cam_") and isinstance(value, dict)),
        key=lambda key: (len(key), key),
    )
    if not tables:
        raise FormatError(path, "no camera tables ([cam_0], [cam_1], ...): not an aniposelib calibration.toml")
    return [_camera(path, key, document[key]) for key in tables]


def read_toml(path: Path) -> dict[str, Any]:
    """A TOML file's document.

    Raises:
        FormatError: unreadable, not UTF-8 or not TOML.
    """
    toml = _toml_reader(path)
    text = read_text(path, "a TOML file")
    try:
        return dict(toml.loads(text))
    except toml.TOMLDecodeError as error:
        raise FormatError(path, f"not valid TOML: {error}") from None


def _toml_reader(path: Path) -> Any:
    """Python's TOML reader (3.11 on; tomli, its backport, before)."""
    try:
        import tomllib

        return tomllib
    except ModuleNotFoundError:  # Python 3.10
        try:
            import tomli  # type: ignore[import-not-found]

            return tomli
        except ModuleNotFoundError:
            raise FormatError(path, "reading TOML needs Python 3.11 or the tomli package (pip install tomli)") from None


def _camera(path: Path, key: str, table: dict[str, Any]) -> GivenIntrinsics:
    if "name" not in table:
        raise FormatError(path, f"[{key}] lacks name")
    return opencv_camera(path, key, table, str(table["name"]))


def opencv_camera(path: Path, key: str, table: dict[str, Any], name: str) -> GivenIntrinsics:
    """A camera table's OpenCV intrinsics: ``size``, ``matrix``, ``distortions`` and ``fisheye`` (aniposelib's
    and caliscope's tables alike).

    Raises:
        FormatError: naming the file, the table ``[key]`` and the key at fault.
    """
    for needed in ("size", "matrix", "distortions"):
        if needed not in table:
            raise FormatError(path, f"[{key}] lacks {needed}")
    size = table["size"]
    if not (isinstance(size, list) and len(size) == 2 and all(isinstance(v, int) and v > 0 for v in size)):
        raise FormatError(path, f"[{key}] size must be [width, height] in pixels, got {size!r}")
    matrix = table["matrix"]
    rows = matrix if isinstance(matrix, list) and len(matrix) == 3 else None
    if rows is None or not all(isinstance(r, list) and len(r) == 3 and all(_number(v) for v in r) for r in rows):
        raise FormatError(path, f"[{key}] matrix must be 3 rows of 3 numbers (K), got {matrix!r}")
    distortion = table["distortions"]
    if not (isinstance(distortion, list) and all(_number(v) for v in distortion)):
        raise FormatError(path, f"[{key}] distortions must be a list of numbers, got {distortion!r}")
    fisheye = table.get("fisheye", False)
    if not isinstance(fisheye, bool):
        raise FormatError(path, f"[{key}] fisheye must be true or false, got {fisheye!r}")
    count = len(distortion)
    if fisheye and count != 4:
        raise FormatError(path, f"[{key}] a fisheye camera has 4 distortions (cv2.fisheye k1..k4), got {count}")
    if not fisheye and count not in (4, 5, 8):
        raise FormatError(path, f"[{key}] distortions must be 4, 5 or 8 of OpenCV's (k1, k2, p1, p2, ...), got {count}")
    model = "equidistant" if fisheye else "rational_polynomial" if count == 8 else "plumb_bob"
    values = tuple(float(v) for v in distortion) + ((0.0,) if model == "plumb_bob" and count == 4 else ())
    return GivenIntrinsics(
        name,
        (int(size[0]), int(size[1])),
        tuple((float(r[0]), float(r[1]), float(r[2])) for r in rows),
        values,
        model,
    )


def _number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and value == value  # (NaN is not)
