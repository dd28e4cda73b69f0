"""Typed records of the calibration input: the wand, the cameras, the observations."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.errors import InsufficientDataError, ModelError
from wand_calib_ros.core.model.camera_model import CameraModel
from wand_calib_ros.core.model.views import whole_views

FloatArray = NDArray[np.float64]

#: Wand point labels in the order used everywhere: A first, then along the wand (A-B-C of the paper's
#: three-LED wand, |AB| = L1, |BC| = L2; wands with more markers go on with D, E, ...).
ALL_POINT_LABELS = ("A", "B", "C", "D", "E", "F", "G", "H")
#: The labels of the paper's three-LED wand.
POINT_LABELS = ALL_POINT_LABELS[:3]

#: Lens hints accepted by ``CameraSpec.lens`` besides the projection names.
LENS_CLASSES = ("fisheye", "conventional")


@dataclass(frozen=True)
class WandSpec:
    """The wand: K >= 2 collinear markers at known positions along it.

    Attributes:
        positions_mm: (K,) position of each marker along the wand, mm: 0 (marker A) first, then
            increasing (the paper's wand: (0, L1, L1 + L2)).
    """

    positions_mm: tuple[float, ...]

    def __post_init__(self) -> None:
        positions = tuple(float(p) for p in self.positions_mm)
        object.__setattr__(self, "positions_mm", positions)
        if not 2 <= len(positions) <= len(ALL_POINT_LABELS):
            raise ModelError(f"a wand has 2 to {len(ALL_POINT_LABELS)} markers, got {len(positions)}")
        if not all(np.isfinite(positions)) or positions[0] != 0.0 or np.any(np.diff(positions) <= 0):
            raise ModelError(f"marker positions must start at 0 mm and increase, got {list(positions)}")

    @classmethod
    def from_lengths(cls, L1: float, L2: float) -> WandSpec:
        """The paper's three-LED wand: |AB| = L1, |BC| = L2 (mm)."""
        if not (np.isfinite(L1) and np.isfinite(L2) and L1 > 0 and L2 > 0):
            raise ModelError(f"wand lengths must be positive, got L1={L1}, L2={L2}")
        return cls((0.0, float(L1), float(L1) + float(L2)))

    @property
    def n_points(self) -> int:
        """K, the number of markers."""
        return len(self.positions_mm)

    @property
    def labels(self) -> tuple[str, ...]:
        """The markers' labels in order (A, B, C, ...)."""
        return ALL_POINT_LABELS[: self.n_points]

    @property
    def L(self) -> float:
        """Distance from the first marker to the last (|AC| of the paper's wand), mm."""
        return self.positions_mm[-1]

    @property
    def ends(self) -> str:
        """The first-to-last distance by the markers' names, as messages write it: |AB| for two markers, |AC|
        for three."""
        return f"|{self.labels[0]}{self.labels[-1]}|"

    @property
    def L1(self) -> float:
        """|AB| in mm (the first segment)."""
        return self.positions_mm[1]

    @property
    def L2(self) -> float:
        """|BC| in mm (the second segment; a two-marker wand has none)."""
        if self.n_points < 3:
            raise ModelError("a two-marker wand has one segment only")
        return self.positions_mm[2] - self.positions_mm[1]

    @property
    def offsets(self) -> FloatArray:
        """(K,) distances of the markers from A along the wand, mm."""
        return np.array(self.positions_mm)

    def three_points(self) -> tuple[int, int, int]:
        """Indices of the three markers the initialisation works with (the paper's method needs three): the
        first, the one nearest the middle and the last (K >= 3)."""
        if self.n_points < 3:
            raise ModelError("the initialisation needs a wand of at least three markers")
        inner = self.offsets[1:-1]
        middle = 1 + int(np.argmin(np.abs(inner - 0.5 * self.L)))
        return 0, middle, self.n_points - 1

    def three_point_wand(self) -> WandSpec:
        """The wand of :meth:`three_points`' markers (the paper's A, B, C)."""
        _, middle, last = self.three_points()
        return WandSpec((0.0, self.positions_mm[middle], self.positions_mm[last]))


@dataclass(frozen=True)
class CameraSpec:
    """What the manufacturer tells about one camera (the rig description).

    Attributes:
        name: camera name used in observations and results.
        image_size: (width, height) in px.
        pixel_size_um: (width, height) of a pixel in micrometres; fixes m = 1000 / pixel size.
        nominal_focal_mm: nominal focal length, mm.
        max_view_angle_deg: theta_max, half the field of view, degrees.
        lens: optional hint: "fisheye", "conventional" or a projection name.
        readout_ms: rolling-shutter readout time of the whole image, ms, held fixed (0: a global
            shutter); None: estimated when the data say so.
        intrinsics: intrinsics the user already has (a board calibration), None: estimated.
        intrinsics_fixed: the given intrinsics are held fixed (only the pose is estimated); False:
            they are the start of the estimate.
        camera_model: the camera model to calibrate it in (one of
            :data:`~wand_calib_ros.core.model.camera_model.CAMERA_MODELS`); None: the given intrinsics' own
            model, else the one the data choose (:mod:`wand_calib_ros.core.initialise.lens_choice`).
    """

    name: str
    image_size: tuple[int, int]
    pixel_size_um: tuple[float, float]
    nominal_focal_mm: float
    max_view_angle_deg: float
    lens: str | None = None
    readout_ms: float | None = None
    intrinsics: CameraModel | None = None
    intrinsics_fixed: bool = True
    camera_model: str | None = None

    @property
    def holds_intrinsics(self) -> bool:
        """Whether this camera's intrinsics are given and held fixed."""
        return self.intrinsics is not None and self.intrinsics_fixed

    @property
    def m(self) -> FloatArray:
        """(2,) pixel densities m_u, m_v in px/mm."""
        return 1000.0 / np.asarray(self.pixel_size_um, dtype=np.float64)

    @property
    def max_view_angle(self) -> float:
        """theta_max in rad."""
        return float(np.radians(self.max_view_angle_deg))

    @property
    def image_center(self) -> FloatArray:
        """(2,) centre of the image in the OpenCV pixel convention."""
        return (np.asarray(self.image_size, dtype=np.float64) - 1.0) / 2.0


@dataclass(frozen=True)
class RigSpec:
    """The calibration input besides the observations.

    Attributes:
        wand: the wand's markers.
        cameras: the cameras, in the order of the observations' axis 1.
        floor_tool: K (x, y, z) the markers of a floor tool (an L-frame, a square of markers) in the world frame
            it defines, mm: the floor frames show it instead of the wand laid on the floor (None: no tool).
            Its markers are the views' points 0..K-1 (A, B, C, ...).
    """

    wand: WandSpec
    cameras: tuple[CameraSpec, ...]
    floor_tool: tuple[tuple[float, float, float], ...] | None = None

    @property
    def camera_names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.cameras)

    @property
    def image_sizes(self) -> dict[str, tuple[int, int]]:
        """Each camera's (width, height) in px, by name."""
        return {c.name: c.image_size for c in self.cameras}

    def camera(self, name: str) -> CameraSpec:
        for spec in self.cameras:
            if spec.name == name:
                return spec
        raise KeyError(name)


@dataclass(frozen=True, eq=False)
class WandObservations:
    """Image points of the wand, dense over frames and cameras.

    Attributes:
        frames: (F,) frame ids as in the observations file. Without stamps, consecutive ids are
            consecutive frames of one recording at a constant rate and a frame's views are
            simultaneous; with stamps, a frame is a grouping of views close in time.
        camera_names: (C,) names; the order of axis 1 of ``uv``.
        uv: (F, C, K, 2) pixels of the wand's K markers (A, B, C, ...); NaN where a camera did not see one.
        stamps: (F, C) capture stamp of each camera's image, seconds (NaN where the camera has no
            view in that frame), or None when the observations carry no stamps.
        saturated: (F, C, K) which points were measured on saturated spots (the detector's flag: their centres
            may be biased, :mod:`~wand_calib_ros.core.judge.centre_bias`), or None: not known.
        brightness: (F, C, K) each point's brightness, stops over full scale (log2 of its spot's peak over the
            image's full scale, :mod:`~wand_calib_ros.core.model.brightness`; NaN where not known), or None: none
            known.
    """

    frames: NDArray[np.int64]
    camera_names: tuple[str, ...]
    uv: FloatArray
    stamps: FloatArray | None = None
    saturated: NDArray[np.bool_] | None = None
    brightness: FloatArray | None = None

    def __post_init__(self) -> None:
        frames = np.asarray(self.frames, dtype=np.int64)
        uv = np.asarray(self.uv, dtype=np.float64)
        if uv.ndim != 4 or uv.shape[:2] != (frames.size, len(self.camera_names)) or uv.shape[3] != 2:
            raise ValueError(
                f"uv must have shape (F, C, K, 2) = ({frames.size}, {len(self.camera_names)}, K, 2), got {uv.shape}"
            )
        frames.setflags(write=False)
        uv.setflags(write=False)
        object.__setattr__(self, "frames", frames)
        object.__setattr__(self, "uv", uv)
        for name, dtype, shape, axes in (
            ("stamps", np.float64, uv.shape[:2], "(F, C)"),
            ("saturated", np.bool_, uv.shape[:3], "(F, C, K)"),
            ("brightness", np.float64, uv.shape[:3], "(F, C, K)"),
        ):
            given = getattr(self, name)
            if given is None:
                continue
            array = np.array(given, dtype=dtype)
            if array.shape != shape:
                raise ValueError(f"{name} must have shape {axes} = {shape}, got {array.shape}")
            array.setflags(write=False)
            object.__setattr__(self, name, array)

    @property
    def complete(self) -> NDArray[np.bool_]:
        """(F, C) True where a camera sees every wand marker."""
        return whole_views(self.uv)

    def camera_index(self, name: str) -> int:
        try:
            return self.camera_names.index(name)
        except ValueError:
            raise InsufficientDataError(f"no observations for camera '{name}'") from None

    def select_frames(self, mask: NDArray[np.bool_] | NDArray[np.int64]) -> WandObservations:
        """A copy restricted to the frames where ``mask`` (F,) is True (or to an index of frames)."""
        stamps = None if self.stamps is None else self.stamps[mask]
        saturated = None if self.saturated is None else self.saturated[mask]
        brightness = None if self.brightness is None else self.brightness[mask]
        return WandObservations(self.frames[mask], self.camera_names, self.uv[mask], stamps, saturated, brightness)

    def select_cameras(self, names: tuple[str, ...]) -> WandObservations:
        """A copy with only the named cameras, in that order (these observations themselves if they are those)."""
        if tuple(names) == self.camera_names:  # a copy of the dense views costs 150 MB at 64 cameras x 50,000 frames
            return self
        index = [self.camera_index(n) for n in names]
        stamps = None if self.stamps is None else self.stamps[:, index]
        saturated = None if self.saturated is None else self.saturated[:, index]
        brightness = None if self.brightness is None else self.brightness[:, index]
        return WandObservations(self.frames, names, self.uv[:, index], stamps, saturated, brightness)

    def with_uv(self, uv: FloatArray) -> WandObservations:
        """The same frames, cameras and stamps with other pixels (F, C, K, 2): each point keeps its saturation flag
        and brightness where it is where one of its view's points was (labels exchanged), else none."""
        return WandObservations(
            self.frames,
            self.camera_names,
            uv,
            self.stamps,
            moved_flags(self.uv, uv, self.saturated),
            moved_values(self.uv, uv, self.brightness),
        )


def moved_flags(old: FloatArray, new: FloatArray, flags: NDArray[np.bool_] | None) -> NDArray[np.bool_] | None:
    """(F, C, K) the flags of ``old`` (F, C, K, 2) points carried to the ``new`` points at the same place in their
    view (within 1e-6 px; False where none was), or None: no flags."""
    return None if flags is None else _moved(old, new, flags, False)


def moved_values(old: FloatArray, new: FloatArray, values: FloatArray | None) -> FloatArray | None:
    """(F, C, K) the values of ``old`` (F, C, K, 2) points carried to the ``new`` points at the same place in their
    view (within 1e-6 px; NaN where none was), or None: no values."""
    return None if values is None else _moved(old, new, values, np.nan)


def _moved(old: FloatArray, new: FloatArray, values: NDArray[Any], fill: Any) -> NDArray[Any]:
    """:func:`moved_flags` and :func:`moved_values`: ``fill`` where no old point was."""
    if old.shape != new.shape:
        return np.full(new.shape[:3], fill, dtype=values.dtype)
    with np.errstate(invalid="ignore"):
        kept = np.all(np.abs(new - old) < 1e-6, axis=-1)  # (F, C, K) the point did not move
    out = np.where(kept, values, fill)
    moved = np.flatnonzero((np.isfinite(new[..., 0]) & ~kept).reshape(-1, new.shape[2]).any(axis=1))
    if moved.size:  # views whose points moved (labels exchanged, a view added): matched by place
        views_old = old.reshape(-1, *old.shape[2:])[moved]
        views_new = new.reshape(-1, *new.shape[2:])[moved]
        gaps = np.linalg.norm(views_new[:, :, None, :] - views_old[:, None, :, :], axis=-1)  # (V, K, K)
        same = np.nan_to_num(gaps, nan=np.inf) < 1e-6  # (V, K new, K old): at most one old point per new one
        source = np.argmax(same, axis=-1)  # (V, K)
        found = same.any(axis=-1)
        old_values = values.reshape(-1, values.shape[2])[moved]
        carried = np.where(found, np.take_along_axis(old_values, source, axis=1), fill)
        out = out.reshape(-1, values.shape[2])
        out[moved] = carried
        out = out.reshape(values.shape)
    return np.asarray(out)


def spread_subset(n: int, size: int) -> NDArray[np.int64]:
    """Indices of ``size`` items spread evenly over ``n`` (all of them when n <= size)."""
    return np.unique(np.linspace(0, n - 1, min(n, size)).round().astype(np.int64))
