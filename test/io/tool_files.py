"""Other tools' files written as their own writer code writes them, from OpenCV pixels and intrinsics (the truth).

Each writer follows the tool's source: Argus's Clicker (``-xypts.csv`` through pandas, a track per marker,
columns sorted by name; bottom left, y up, pixel edges at whole numbers) and its wand calibration's profiles
(``-clicker-profile.txt``, ``-sba-profile.txt``), Argus's paired-points export (``pt1_cam1_x``, 0-based, its y
flip ``height - y``), DLTdv (``pt1_cam1_X``, MATLAB's 1-based pixels; 8 from the top left, up to 7 from the
bottom left), easyWand 5 and 6 data files, and pyOpenLPT's ``export_wand_data``.
"""

from __future__ import annotations

import csv
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from wand_calib_ros.core.model.camera_model import CameraModel, to_opencv


def _opencv(model: CameraModel) -> tuple[np.ndarray, np.ndarray]:
    opencv = to_opencv(model)
    return np.asarray(opencv.camera_matrix, dtype=float), np.asarray(opencv.distortion, dtype=float)


def clicker_xy(uv: np.ndarray, heights: Sequence[int]) -> np.ndarray:
    """(F, C, K, 2) Argus Clicker's coordinates of OpenCV pixels: x = u + 0.5, y = height - 0.5 - v."""
    h = np.asarray(heights, dtype=float)[None, :, None]
    return np.stack([uv[..., 0] + 0.5, h - 0.5 - uv[..., 1]], axis=-1)


def argus_clicker_points(path: Path, uv: np.ndarray, heights: Sequence[int], tracks: Sequence[str]) -> None:
    """Argus Clicker's ``-xypts.csv``: a dict of ``<track>_cam_<N>_x/_y`` columns, a DataFrame with its columns
    sorted, ``to_csv(index=False, na_rep='NaN')``."""
    import pandas

    xy = clicker_xy(uv, heights)
    common = {}
    for p, track in enumerate(tracks):
        for c in range(uv.shape[1]):
            common[f"{track}_cam_{c + 1}_x"] = xy[:, c, p, 0]
            common[f"{track}_cam_{c + 1}_y"] = xy[:, c, p, 1]
    pandas.DataFrame({key: common[key] for key in sorted(common)}).to_csv(path, index=False, na_rep="NaN")


def argus_clicker_profile(path: Path, models: Sequence[CameraModel]) -> None:
    """Argus's ``-clicker-profile.txt`` (pandas, spaces, no header) in its Clicker's pixel frame: number, f,
    twice the principal point, cx, cy, aspect, r2, r4, t1, t2, r6 (t1 and cy flipped with y)."""
    import pandas

    rows = []
    for number, model in enumerate(models, start=1):
        K, D = _opencv(model)
        cx, cy = K[0, 2] + 0.5, model.image_size[1] - 0.5 - K[1, 2]
        rows.append([number, K[0, 0], 2 * cx, 2 * cy, cx, cy, K[1, 1] / K[0, 0], D[0], D[1], -D[2], D[3], D[4]])
    pandas.DataFrame(rows).to_csv(path, header=False, index=False, sep=" ")


def argus_sba_profile(path: Path, models: Sequence[CameraModel], rng: np.random.Generator) -> None:
    """Argus's ``-sba-profile.txt``: a row per camera, f cx cy AR skew r2 r4 t1 t2 r6 q0 qi qj qk tx ty tz, in
    its Clicker's pixel frame (the pose a random one: not read)."""
    import pandas

    rows = []
    for model in models:
        K, D = _opencv(model)
        cx, cy = K[0, 2] + 0.5, model.image_size[1] - 0.5 - K[1, 2]
        q = rng.normal(size=4)
        pose = [*(q / np.linalg.norm(q)), *rng.uniform(-2, 2, 3)]
        rows.append([K[0, 0], cx, cy, K[1, 1] / K[0, 0], 0.0, D[0], D[1], -D[2], D[3], D[4], *pose])
    pandas.DataFrame(rows).to_csv(path, header=False, index=False, sep=" ")


def argus_paired_points(path: Path, uv: np.ndarray, heights: Sequence[int], *, flip_y: bool) -> None:
    """Argus's paired points export: csv.writer, ``pt1_cam<C>_x/_y`` of every camera then ``pt2``, OpenCV's
    pixels or, with its y flip, y = height - v."""
    n_cameras = uv.shape[1]
    header = [f"pt{p}_cam{c + 1}_{a}" for p in (1, 2) for c in range(n_cameras) for a in "xy"]
    with path.open("w", newline="") as stream:
        writer = csv.writer(stream)
        writer.writerow(header)
        for frame in uv:
            row = []
            for p in (0, 1):
                for c in range(n_cameras):
                    u, v = frame[c, p]
                    row += [u, heights[c] - v if flip_y else v]
            writer.writerow(row)


def dltdv_points(path: Path, uv: np.ndarray, heights: Sequence[int], *, version: int) -> None:
    """DLTdv's ``xypts.csv``: ``pt<P>_cam<C>_X/_Y`` (each point, every camera), MATLAB's 1-based pixels, from the
    top left (DLTdv 8) or the bottom left (up to 7: y = height - v), NaN where not digitised."""
    _, n_cameras, n_points, _ = uv.shape
    header = [f"pt{p + 1}_cam{c + 1}_{a}" for p in range(n_points) for c in range(n_cameras) for a in "XY"]
    lines = [",".join(header)]
    for frame in uv:
        cells = []
        for p in range(n_points):
            for c in range(n_cameras):
                u, v = frame[c, p]
                y = v + 1 if version >= 8 else heights[c] - v
                cells += ["NaN", "NaN"] if not np.isfinite(u) else [repr(float(u + 1)), repr(float(y))]
        lines.append(",".join(cells))
    path.write_text("\n".join(lines) + "\n")


def matlab_xy(uv: np.ndarray, heights: Sequence[int], *, lower_left: bool) -> np.ndarray:
    """(F, C, K, 2) DLTdv's (MATLAB's 1-based) coordinates of OpenCV pixels."""
    h = np.asarray(heights, dtype=float)[None, :, None]
    return np.stack([uv[..., 0] + 1, h - uv[..., 1] if lower_left else uv[..., 1] + 1], axis=-1)


def matlab_intrinsics(model: CameraModel, *, lower_left: bool) -> tuple[float, np.ndarray, np.ndarray]:
    """A camera's f, [Uo Vo] and nlin (k1 k2 p1 p2 k3) in DLTdv's pixel frame."""
    K, D = _opencv(model)
    height = model.image_size[1]
    principal = np.array([K[0, 2] + 1, height - K[1, 2] if lower_left else K[1, 2] + 1])
    nlin = np.array([D[0], D[1], -D[2] if lower_left else D[2], D[3], D[4]])
    return float(K[0, 0]), principal, nlin


def wand_points_table(xy: np.ndarray) -> np.ndarray:
    """(F, 4C) easyWand's wand points: the first marker's x, y in every camera, then the second's."""
    return xy.transpose(0, 2, 1, 3).reshape(len(xy), -1)


def easywand5(path: Path, xy: np.ndarray, models: Sequence[CameraModel] | None, *, lower_left: bool) -> None:
    """easyWand 5's ``_easyWandData.mat`` (``savemat``): its wand points and, given models, the profile it held."""
    from scipy.io import savemat

    fields: dict[str, object] = {
        "wandPts": wand_points_table(xy),
        "imageWidth": np.array([float(m.image_size[0]) for m in models or []]),
        "imageHeight": np.array([float(m.image_size[1]) for m in models or []]),
        "nCams": float(xy.shape[1]),
    }
    if models is not None:
        parts = [matlab_intrinsics(m, lower_left=lower_left) for m in models]
        fields["focalLengths"] = np.array([[f for f, _, _ in parts]])
        fields["principalPoints"] = np.concatenate([p for _, p, _ in parts])  # u, v of each camera in turn
        fields["nlin"] = np.array([n for _, _, n in parts])
    else:
        del fields["imageWidth"], fields["imageHeight"]
    savemat(path, {"easyWandData": fields})


def easywand6(
    path: Path, xy: np.ndarray, rows: np.ndarray, models: Sequence[CameraModel] | None, *, lower_left: bool
) -> None:
    """easyWand 6's ``_easyWand6Data.mat``: MATLAB 7.3 (HDF5 with MATLAB's header and classes, arrays stored
    column-major, a struct array's fields as references to each element's value)."""
    import h5py

    def double(group: h5py.Group, name: str, value: np.ndarray) -> None:
        group.create_dataset(name, data=np.atleast_2d(value).T).attrs["MATLAB_class"] = np.bytes_("double")

    with h5py.File(path, "w", userblock_size=512) as mat:
        wand = mat.create_group("ew6Save/data/wandPts")
        for group in (mat["ew6Save"], mat["ew6Save/data"], wand):
            group.attrs["MATLAB_class"] = np.bytes_("struct")
        double(wand, "data", wand_points_table(xy))
        double(wand, "ID", (rows + 1.0)[:, None])
        double(mat["ew6Save/data"], "imageOriginLowerLeft", np.array([[1.0 if lower_left else 0.0]]))
        if models is not None:
            intrinsics = mat.create_group("ew6Save/data/intrinsics")
            intrinsics.attrs["MATLAB_class"] = np.bytes_("struct")
            refs = mat.require_group("#refs#")
            values: dict[str, list[np.ndarray]] = {}
            for model in models:
                f, principal, nlin = matlab_intrinsics(model, lower_left=lower_left)
                values.setdefault("FocalLength", []).append(np.array([f, f]))
                values.setdefault("PrincipalPoint", []).append(principal)
                values.setdefault("RadialDistortion", []).append(nlin[[0, 1, 4]])
                values.setdefault("TangentialDistortion", []).append(nlin[[2, 3]])
                values.setdefault("Skew", []).append(np.array([0.0]))
            for name, items in values.items():
                references = []
                for index, value in enumerate(items):
                    dataset = refs.create_dataset(f"{name}{index}", data=value[:, None])
                    dataset.attrs["MATLAB_class"] = np.bytes_("double")
                    references.append(dataset.ref)
                field = intrinsics.create_dataset(name, (len(items), 1), dtype=h5py.ref_dtype)
                field[:, 0] = references
    with path.open("r+b") as stream:  # MATLAB's text header in the user block
        stream.write(b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Fri Dec  4 12:00:00 2026 HDF5 schema 1.00 .")


def openlpt_wand_data(path: Path, uv: np.ndarray, rng: np.random.Generator) -> tuple[int, int]:
    """pyOpenLPT's ``export_wand_data``: a Raw row for every circle found (the wand's balls and some stray ones,
    ``PointIdx`` counting them), then Filtered_Small (0) and Filtered_Large (1) of the frames its filter
    validated (every camera with both balls in them, one ball in some). Returns (raw rows, one-ball views)."""
    raw_rows, single = 0, 0
    with path.open("w", newline="") as stream:
        writer = csv.writer(stream)
        writer.writerow(["Frame", "Camera", "Status", "PointIdx", "X", "Y", "Radius", "Metric"])
        for f in range(len(uv)):
            for c in range(uv.shape[1]):
                found = [uv[f, c, p] for p in range(uv.shape[2]) if np.isfinite(uv[f, c, p, 0])]
                found += [rng.uniform([0, 0], [600, 400]) for _ in range(rng.integers(0, 3))]  # stray circles
                for index, (x, y) in enumerate(found):
                    writer.writerow([f, c, "Raw", index, f"{x:.3f}", f"{y:.3f}", f"{rng.uniform(5, 30):.3f}", "0.9000"])
                    raw_rows += 1
        for f in range(len(uv)):
            for c in range(uv.shape[1]):
                balls = [p for p in range(uv.shape[2]) if np.isfinite(uv[f, c, p, 0])]
                if not balls:
                    continue
                single += len(balls) == 1
                for p in balls:
                    x, y = uv[f, c, p]
                    status = ("Filtered_Small", "Filtered_Large")[p]
                    writer.writerow([f, c, status, p, f"{x:.3f}", f"{y:.3f}", f"{10.0 + 5 * p:.3f}", "0.9500"])
    return raw_rows, single
