"""easyWand's wand data file: the wand points of a project, as easyWand saves it.

- easyWand 5 saves ``<name>_easyWandData.mat`` (MATLAB 5.0 MAT-file): a struct ``easyWandData`` whose
  ``wandPts`` has a row per frame and 4 columns per camera (the first marker's x, y in every camera, then
  the second's: DLTdv's and Argus's paired-points layout), with ``imageWidth`` / ``imageHeight`` per
  camera; pixels with the origin at the image's bottom left (DLTdv's), unless told otherwise.
- easyWand 6 saves ``<name>_easyWand6Data.mat`` (MATLAB 7.3, an HDF5 file): ``ew6Save.data.wandPts`` with
  ``data`` (the same table), ``ID`` (each row's 1-based row in the points file it was loaded from) and
  ``ew6Save.data.imageOriginLowerLeft`` (1: bottom-left origin; 0: top-left, its default).

Other fields (easyWand's own calibration) are not read. Camera C is the rig's C-th camera; frame ids are
the rows of the points file (``ID - 1``) where the file keeps them, else the table's rows.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.model.rig import RigSpec, WandObservations
from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.imports.xypts import from_bottom_left

FloatArray = NDArray[np.float64]


def read_easywand(path: str | Path, rig: RigSpec, *, origin: str | None = None) -> WandObservations:
    """The observations of an easyWand data file.

    Args:
        origin: "bottom-left" or "top-left" to override the file's pixel origin (None: as the file says,
            bottom-left for easyWand 5).

    Raises:
        FormatError: naming the file and what it lacks.
    """
    path = Path(path)
    try:
        with path.open("rb") as stream:
            header = stream.read(128)
    except OSError as error:
        raise FormatError(path, f"cannot read: {error.strerror}") from None
    if header.startswith(b"MATLAB 7.3"):
        table, frames, lower_left, sizes = _easywand6(path)
    elif header.startswith(b"MATLAB 5.0"):
        table, frames, lower_left, sizes = _easywand5(path)
    else:
        raise FormatError(path, "not a MATLAB data file (easyWand's <name>_easyWandData.mat or _easyWand6Data.mat)")
    n_cameras = len(rig.cameras)
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
    uv = table.reshape(len(table), rig.wand.n_points, n_cameras, 2).transpose(0, 2, 1, 3).astype(np.float64)
    if lower_left if origin is None else origin == "bottom-left":
        uv = from_bottom_left(uv, rig)
    seen = np.any(np.isfinite(uv), axis=(1, 2, 3))
    if not seen.any():
        raise FormatError(path, "no marker is seen in any frame")
    return WandObservations(frames[seen], rig.camera_names, uv[seen])


def _easywand5(path: Path) -> tuple[FloatArray, NDArray[np.int64], bool, NDArray[np.int64] | None]:
    from scipy.io import loadmat

    try:
        content = loadmat(path, squeeze_me=True, struct_as_record=False)
    except (ValueError, TypeError, OSError) as error:
        raise FormatError(path, f"cannot read the MATLAB file: {error}") from None
    if "easyWandData" not in content:
        raise FormatError(path, "no easyWandData in it (an easyWand 5 <name>_easyWandData.mat?)")
    data = content["easyWandData"]
    table = _field(path, data, "wandPts", "easyWandData")
    sizes = None
    if hasattr(data, "imageWidth") and hasattr(data, "imageHeight"):
        sizes = np.stack([np.atleast_1d(data.imageWidth), np.atleast_1d(data.imageHeight)], axis=1).astype(np.int64)
    table = np.atleast_2d(np.asarray(table, dtype=np.float64))
    return table, np.arange(len(table), dtype=np.int64), True, sizes


def _easywand6(path: Path) -> tuple[FloatArray, NDArray[np.int64], bool, NDArray[np.int64] | None]:
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
            lower_left = bool(np.asarray(flag).reshape(-1)[0]) if flag is not None else False
    except OSError as error:
        raise FormatError(path, f"cannot read the MATLAB 7.3 file: {error}") from None
    if rows is None or rows.size != len(table):
        return table, np.arange(len(table), dtype=np.int64), lower_left, None
    return table, rows.astype(np.int64), lower_left, None


def _field(path: Path, struct: Any, name: str, owner: str) -> Any:
    if not hasattr(struct, name):
        raise FormatError(path, f"{owner} has no {name}")
    return getattr(struct, name)
