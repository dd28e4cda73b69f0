"""Typed records of the calibration input: the wand, the cameras, the observations."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.camera_model import CameraModel
from wand_calib_ros.core.errors import InsufficientDataError, ModelError

FloatArray = NDArray[np.float64]

#: Wand point labels in the order used everywhere (A-B-C collinear, |AB| = L1, |BC| = L2).
POINT_LABELS = ("A", "B", "C")

#: Lens hints accepted by ``CameraSpec.lens`` besides the projection names.
LENS_CLASSES = ("fisheye", "conventional")


@dataclass(frozen=True)
class WandSpec:
    """The wand: three collinear points with |AB| = L1 and |BC| = L2 (mm)."""

    L1: float
    L2: float

    def __post_init__(self) -> None:
        if not (np.isfinite(self.L1) and np.isfinite(self.L2) and self.L1 > 0 and self.L2 > 0):
            raise ModelError(f"wand lengths must be positive, got L1={self.L1}, L2={self.L2}")

    @property
    def L(self) -> float:
        """|AC| = L1 + L2 in mm."""
        return self.L1 + self.L2

    @property
    def offsets(self) -> FloatArray:
        """(3,) distances of A, B, C from A along the wand, mm."""
        return np.array([0.0, self.L1, self.L])


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
    """The calibration input besides the observations."""

    wand: WandSpec
    cameras: tuple[CameraSpec, ...]

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
        uv: (F, C, 3, 2) pixels of A, B, C; NaN where a camera did not see a point.
        stamps: (F, C) capture stamp of each camera's image, seconds (NaN where the camera has no
            view in that frame), or None when the observations carry no stamps.
    """

    frames: NDArray[np.int64]
    camera_names: tuple[str, ...]
    uv: FloatArray
    stamps: FloatArray | None = None

    def __post_init__(self) -> None:
        frames = np.asarray(self.frames, dtype=np.int64)
        uv = np.asarray(self.uv, dtype=np.float64)
        if uv.shape != (frames.size, len(self.camera_names), 3, 2):
            raise ValueError(
                f"uv must have shape (F, C, 3, 2) = ({frames.size}, {len(self.camera_names)}, 3, 2), got {uv.shape}"
            )
        frames.setflags(write=False)
        uv.setflags(write=False)
        object.__setattr__(self, "frames", frames)
        object.__setattr__(self, "uv", uv)
        if self.stamps is not None:
            stamps = np.array(self.stamps, dtype=np.float64)
            if stamps.shape != uv.shape[:2]:
                raise ValueError(f"stamps must have shape (F, C) = {uv.shape[:2]}, got {stamps.shape}")
            stamps.setflags(write=False)
            object.__setattr__(self, "stamps", stamps)

    @property
    def complete(self) -> NDArray[np.bool_]:
        """(F, C) True where a camera sees all three wand points."""
        return np.all(np.isfinite(self.uv), axis=(2, 3))

    def camera_index(self, name: str) -> int:
        try:
            return self.camera_names.index(name)
        except ValueError:
            raise InsufficientDataError(f"no observations for camera '{name}'") from None

    def select_frames(self, mask: NDArray[np.bool_] | NDArray[np.int64]) -> WandObservations:
        """A copy restricted to the frames where ``mask`` (F,) is True (or to an index of frames)."""
        stamps = None if self.stamps is None else self.stamps[mask]
        return WandObservations(self.frames[mask], self.camera_names, self.uv[mask], stamps)

    def select_cameras(self, names: tuple[str, ...]) -> WandObservations:
        """A copy with only the named cameras, in that order."""
        index = [self.camera_index(n) for n in names]
        stamps = None if self.stamps is None else self.stamps[:, index]
        return WandObservations(self.frames, names, self.uv[:, index], stamps)

    def with_uv(self, uv: FloatArray) -> WandObservations:
        """The same frames, cameras and stamps with other pixels (F, C, 3, 2)."""
        return WandObservations(self.frames, self.camera_names, uv, self.stamps)


def spread_subset(n: int, size: int) -> NDArray[np.int64]:
    """Indices of ``size`` items spread evenly over ``n`` (all of them when n <= size)."""
    return np.unique(np.linspace(0, n - 1, min(n, size)).round().astype(np.int64))
