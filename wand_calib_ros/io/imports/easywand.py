"""easyWand's wand data file: the wand points of a project and the cameras' intrinsics it held.

- easyWand 5 saves ``<name>_easyWandData.mat`` (MATLAB 5.0 MAT-file): a struct ``easyWandData`` whose
  ``wandPts`` has a row per frame and 4 columns per camera (the first marker's x, y in every camera, then
  the second's: DLTdv's and Argus's paired-points layout), with ``imageWidth`` / ``imageHeight`` per
  camera and, where it holds them, the cameras' ``focalLengths`` (px), ``principalPoints`` (u, v of each
  camera in turn) and ``nlin`` (k1, k2, p1, p2, k3 of each camera: OpenCV's plumb_bob). Its pixel origin is
  not written.
- easyWand 6 saves ``<name>_easyWand6Data.mat`` (MATLAB 7.3, an HDF5 file): ``ew6Save.data.wandPts`` with
  ``data`` (the same table), ``ID`` (each row's 1-based row in the points file it was loaded from),
  ``ew6Save.data.imageOriginLowerLeft`` (1: bottom-left origin, its default; 0: top-left) and
  ``ew6Save.data.intrinsics``, a struct per camera (``FocalLength``, ``PrincipalPoint`` [Uo Vo],
  ``RadialDistortion`` [k1 k2 k3], ``TangentialDistortion``, ``Skew``).

Points and principal points are DLTdv's: MATLAB's 1-based pixels (:data:`~wand_calib_ros.io.imports.pixels.MATLAB`).
easyWand's own calibration (its DLT and poses) is not read. Camera C is the rig's C-th camera; frame ids are
the rows of the points file (``ID - 1``) where the file keeps them, else the table's rows.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.model.rig import RigSpec
from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.imports.given import GivenIntrinsics
from wand_calib_ros.io.imports.pixels import MATLAB, WrittenPoints

FloatArray = NDArray[np.float64]


def read_easywand(path: str | Path, rig: RigSpec) -> WrittenPoints:
    """The points (and the intrinsics, where it holds them) of an easyWand data file, as written.

    Raises:
        FormatError: naming the file and what it lacks.
    """
    path = Path(path)
    try:
        with path.open("rb") as stream:
            header = stream.read(128)
    except OSError as error:
        raise FormatError(path, f"cannot read: {error.strerror}") from None
    n_cameras = len(rig.cameras)
    if header.startswith(b"MATLAB 7.3"):
        table, frames, lower_left, sizes, intrinsics = _easywand6(path, n_cameras)
        writer = "easyWand 6's wand points"
    elif header.startswith(b"MATLAB 5.0"):
        table, frames, lower_left, sizes, intrinsics = _easywand5(path, n_cameras)
        writer = "easyWand 5's wand points"
    else:
        raise FormatError(path, "not a MATLAB data file (easyWand's <name>_easyWandData.mat or _easyWand6Data.mat)")
    if table.ndim != 2 or table.shape[1] != 2 * rig.wand.n_points * n_cameras:
        raise FormatError(
            path,
            f"its wand points have {table.shape[-1]} columns; {rig.wand.n_points} markers in {n_cameras} cameras "
            f"take {2 * rig.wand.n_points * n_cameras}",
        )
    if sizes is not None:
        for spec, size in zip(rig.cameras, sizes, strict=True):
            if tuple(size) != spec.image_size:
                raise FormatError(
                    path, f"camera '{spec.name}' is {size[0]}x{size[1]} there, {spec.image_size[0]}x"
                    f"{spec.image_size[1]} in the rig description"
                )  # fmt: skip
    xy = table.reshape(len(table), rig.wand.n_points, n_cameras, 2).transpose(0, 2, 1, 3).astype(np.float64)
    seen = np.any(np.isfinite(xy), axis=(1, 2, 3))
    if not seen.any():
        raise FormatError(path, "no marker is seen in any frame")
    pixels = MATLAB if lower_left is None else MATLAB.with_origin("bottom-left" if lower_left else "top-left")
    return WrittenPoints(frames[seen], xy[seen], pixels, writer, intrinsics)


def _camera(number: int, focal: float, principal: FloatArray, distortion: FloatArray, size: Any) -> GivenIntrinsics:
    """One camera's intrinsics as easyWand holds them (its size where the file writes it, else twice the
    principal point, as easyWand 6 assumes)."""
    u, v = (float(x) for x in principal)
    written = size is not None
    width, height = (int(size[0]), int(size[1])) if written else (round(2 * u), round(2 * v))
    return GivenIntrinsics(
        f"cam{number}",
        (width, height),
        ((float(focal), 0.0, u), (0.0, float(focal), v), (0.0, 0.0, 1.0)),
        tuple(float(d) for d in distortion),
        "plumb_bob",
        0.0 if written else math.inf,
    )


def _per_camera(path: Path, values: Any, name: str, n_cameras: int, width: int) -> FloatArray:
    """(C, width) a field holding ``width`` numbers per camera, whichever way MATLAB laid them out."""
    array = np.asarray(values, dtype=np.float64)
    if array.size != n_cameras * width:
        raise FormatError(
            path, f"easyWandData.{name} has {array.size} values; {n_cameras} cameras take {n_cameras * width}"
        )
    if array.ndim == 2 and array.shape == (width, n_cameras) and width != n_cameras:
        return array.T.copy()
    return array.reshape(n_cameras, width)


def _easywand5(
    path: Path, n_cameras: int
) -> tuple[FloatArray, NDArray[np.int64], bool | None, NDArray[np.int64] | None, tuple[GivenIntrinsics, ...] | None]:
    from scipy.io import loadmat

    try:
        content = loadmat(path, squeeze_me=True, struct_as_record=False)
    except (ValueError, TypeError, OSError) as error:
        raise FormatError(path, f"cannot read the MATLAB file: {error}") from None
    if "easyWandData" not in content:
        raise FormatError(path, "no easyWandData in it (an easyWand 5 <name>_easyWandData.mat?)")
    data = content["easyWandData"]
    if not hasattr(data, "wandPts"):
        raise FormatError(path, "easyWandData has no wandPts")
    table = np.atleast_2d(np.asarray(data.wandPts, dtype=np.float64))
    sizes = None
    if hasattr(data, "imageWidth") and hasattr(data, "imageHeight"):
        sizes = np.stack([np.atleast_1d(data.imageWidth), np.atleast_1d(data.imageHeight)], axis=1).astype(np.int64)
    intrinsics = None
    if all(hasattr(data, name) for name in ("focalLengths", "principalPoints", "nlin")):
        focal = _per_camera(path, data.focalLengths, "focalLengths", n_cameras, 1)[:, 0]
        principal = _per_camera(path, data.principalPoints, "principalPoints", n_cameras, 2)
        nlin = _per_camera(path, data.nlin, "nlin", n_cameras, 5)
        intrinsics = tuple(
            _camera(c + 1, focal[c], principal[c], nlin[c], None if sizes is None else sizes[c])
            for c in range(n_cameras)
        )
    return table, np.arange(len(table), dtype=np.int64), None, sizes, intrinsics


def _easywand6(
    path: Path, n_cameras: int
) -> tuple[FloatArray, NDArray[np.int64], bool | None, NDArray[np.int64] | None, tuple[GivenIntrinsics, ...] | None]:
    try:
        import h5py
    except ModuleNotFoundError:
        raise FormatError(
            path, "an easyWand 6 file is MATLAB 7.3 (HDF5): reading it needs h5py (pip install h5py)"
        ) from None
    try:
        with h5py.File(path, "r") as mat:
            group = mat.get("ew6Save/data/wandPts")
            if group is None or "data" not in group:
                raise FormatError(path, "no ew6Save.data.wandPts.data in it (an easyWand 6 project?)")
            table = np.asarray(group["data"], dtype=np.float64).T  # MATLAB stores its arrays column-major
            rows = np.asarray(group["ID"], dtype=np.float64).reshape(-1) - 1 if "ID" in group else None
            flag = mat.get("ew6Save/data/imageOriginLowerLeft")
            lower_left = bool(np.asarray(flag).reshape(-1)[0]) if flag is not None else None
            intrinsics = _easywand6_intrinsics(path, mat, n_cameras)
    except OSError as error:
        raise FormatError(path, f"cannot read the MATLAB 7.3 file: {error}") from None
    if rows is None or rows.size != len(table):
        rows = np.arange(len(table), dtype=np.float64)
    return table, rows.astype(np.int64), lower_left, None, intrinsics


def _easywand6_intrinsics(path: Path, mat: Any, n_cameras: int) -> tuple[GivenIntrinsics, ...] | None:
    """The cameras of ``ew6Save.data.intrinsics`` (a struct array: each field a dataset of references to each
    camera's value; a single camera's struct holds its values directly), or None where it has none."""
    group = mat.get("ew6Save/data/intrinsics")
    if group is None or "FocalLength" not in group:
        return None

    def values(name: str) -> list[FloatArray]:
        if name not in group:
            raise FormatError(path, f"ew6Save.data.intrinsics has no {name}")
        field = group[name]
        if field.dtype.kind == "O":  # references, one per camera
            return [np.asarray(mat[ref], dtype=np.float64).reshape(-1) for ref in np.asarray(field).reshape(-1)]
        return [np.asarray(field, dtype=np.float64).reshape(-1)]

    focal, principal, radial = values("FocalLength"), values("PrincipalPoint"), values("RadialDistortion")
    tangential = values("TangentialDistortion") if "TangentialDistortion" in group else [np.zeros(2)] * len(focal)
    if len(focal) != n_cameras:
        raise FormatError(path, f"ew6Save.data.intrinsics holds {len(focal)} cameras, the rig {n_cameras}")
    cameras = []
    for c in range(n_cameras):
        k = np.zeros(3)
        k[: min(3, radial[c].size)] = radial[c][:3]
        p = np.zeros(2)
        p[: min(2, tangential[c].size)] = tangential[c][:2]
        cameras.append(_camera(c + 1, focal[c][0], principal[c][:2], np.array([k[0], k[1], p[0], p[1], k[2]]), None))
    return tuple(cameras)
