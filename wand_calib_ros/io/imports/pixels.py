"""Where other tools put a pixel: their image origin and pixel centres, and the conversion to OpenCV's.

OpenCV (and this package) puts the origin at the image's top left, y down, and the first pixel's centre at
(0, 0). Other tools differ in two ways, each fixed by how they draw or index an image:

- the origin: top left, y down (OpenCV, DLTdv 8, caliscope, pyOpenLPT) or bottom left, y up (Argus's
  Clicker, DLTdv up to 7);
- the coordinates of the pixel centre in the origin's corner: 0 (OpenCV, Python tools), 1 (MATLAB's 1-based
  pixels: DLTdv, easyWand) or 0.5 (Argus's Clicker, whose pixel edges lie at whole numbers).

A pixel (u, v) of OpenCV's is then at x = u + first_x and, from the top, y = v + first_y; from the bottom,
y = (height - 1 - v) + first_y. A camera's intrinsics written in the same frame as its points convert with
them: the principal point as a point, and under a flip of y the normalised y changes sign, so the tangential
p1 (OpenCV's order k1, k2, p1, p2, ...) and the skew change sign.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.io.imports.given import GivenIntrinsics

FloatArray = NDArray[np.float64]

#: The image origins a tool may use.
ORIGINS = ("bottom-left", "top-left")


@dataclass(frozen=True)
class PixelFrame:
    """How a tool writes a pixel's position.

    Attributes:
        origin: "top-left" (y down), "bottom-left" (y up), or None where the file does not say.
        first: (x, y) the tool's coordinates of the pixel centre in its origin's corner (px).
        first_from_bottom: from a bottom-left origin, the y of the bottom row's centre where it is not
            ``first[1]`` (Argus's y flip writes height - v: 1 while its x counts from 0), else None.
    """

    origin: str | None
    first: tuple[float, float]
    first_from_bottom: float | None = None

    def __post_init__(self) -> None:
        if self.origin is not None and self.origin not in ORIGINS:
            raise ValueError(f"origin must be one of {ORIGINS} or None, got {self.origin!r}")

    def with_origin(self, origin: str) -> PixelFrame:
        """The same pixel centres from ``origin``."""
        return replace(self, origin=origin)

    def first_y(self) -> float:
        """The y of the first row's centre from the origin (its origin known)."""
        if self.origin == "bottom-left" and self.first_from_bottom is not None:
            return self.first_from_bottom
        return self.first[1]


#: OpenCV's pixels (and those of Python tools: caliscope, pyOpenLPT, aniposelib).
OPENCV = PixelFrame("top-left", (0.0, 0.0))
#: MATLAB's 1-based pixels (DLTdv, easyWand), whose origin the files do not say (DLTdv 8: top left; up to 7:
#: bottom left).
MATLAB = PixelFrame(None, (1.0, 1.0))
#: Argus's Clicker: bottom left, y up, pixel edges at whole numbers (its OpenGL view's coordinates).
ARGUS_CLICKER = PixelFrame("bottom-left", (0.5, 0.5))


def _known(frame: PixelFrame) -> str:
    if frame.origin is None:
        raise ValueError("the pixel origin is not known: choose one first (PixelFrame.with_origin)")
    return frame.origin


def to_opencv(xy: FloatArray, heights: FloatArray, frame: PixelFrame) -> FloatArray:
    """OpenCV pixels of a tool's.

    Args:
        xy: (F, C, K, 2) the tool's coordinates (NaN stays NaN).
        heights: (C,) each camera's image height, px.
        frame: how the tool writes them (its origin known).

    Returns:
        (F, C, K, 2) u, v.
    """
    origin = _known(frame)
    out = np.array(xy, dtype=np.float64)
    out[..., 0] -= frame.first[0]
    if origin == "top-left":
        out[..., 1] -= frame.first_y()
    else:
        out[..., 1] = (np.asarray(heights, dtype=np.float64)[None, :, None] - 1.0 + frame.first_y()) - out[..., 1]
    return out


def intrinsics_to_opencv(camera: GivenIntrinsics, height: int, frame: PixelFrame) -> GivenIntrinsics:
    """A camera's intrinsics written in a tool's pixel frame, in OpenCV's.

    Args:
        camera: K and D as the tool wrote them (D in OpenCV's order for pinhole models).
        height: the camera's image height, px.
        frame: the tool's pixel frame (its origin known).
    """
    origin = _known(frame)
    K = np.array(camera.camera_matrix, dtype=np.float64)
    D = np.array(camera.distortion, dtype=np.float64)
    K[0, 2] -= frame.first[0]
    if origin == "top-left":
        K[1, 2] -= frame.first_y()
    else:
        K[1, 2] = height - 1.0 + frame.first_y() - K[1, 2]
        K[0, 1] = -K[0, 1]
        if camera.distortion_model != "equidistant" and D.size >= 3:
            D[2] = -D[2]
    return replace(
        camera,
        camera_matrix=tuple((float(row[0]), float(row[1]), float(row[2])) for row in K),
        distortion=tuple(float(v) for v in D),
    )


@dataclass(frozen=True, eq=False)
class WrittenPoints:
    """A file's wand points as the tool wrote them, before they are taken into OpenCV's frame.

    Attributes:
        frames: (F,) frame ids.
        xy: (F, C, K, 2) the tool's coordinates of the rig's cameras and markers; NaN where not seen.
        pixels: the tool's pixel frame (its origin None where the file does not say).
        writer: the tool and format, in words (for messages).
        intrinsics: the cameras' intrinsics the file carries, in the same pixel frame and the rig's camera
            order, or None.
    """

    frames: NDArray[np.int64]
    xy: FloatArray
    pixels: PixelFrame
    writer: str
    intrinsics: tuple[GivenIntrinsics, ...] | None = None

    def uv(self, heights: FloatArray, origin: str | None = None) -> FloatArray:
        """(F, C, K, 2) OpenCV pixels, from ``origin`` (None: the file's own, which must be known)."""
        return to_opencv(self.xy, heights, self.pixels if origin is None else self.pixels.with_origin(origin))
