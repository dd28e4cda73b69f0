"""Diagnostics of a finished calibration that the residuals alone reveal.

Clock offset: a camera whose shutter fires ``dt`` frames late (or early)
sees the moving wand where it was ``dt`` frames earlier (later). Its points,
compared with the wand triangulated from the *other* cameras, then leave a
residual proportional to the wand's image velocity: ``r = -dt * v``. A strong
correlation between residuals and velocity, and a drop of the residual once
``dt * v`` is removed, say that the recording is not synchronised.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.camera_model import project, unproject
from wand_calib_ros.core.geometry import triangulate
from wand_calib_ros.core.result import CalibrationResult, ClockOffset
from wand_calib_ros.core.rig import WandObservations, spread_subset

FloatArray = NDArray[np.float64]

#: Frames (spread over the recording) used for the estimate.
MAX_FRAMES = 3000
#: A camera is reported when residual and velocity correlate at least this much ...
CLOCK_CORRELATION = 0.7
#: ... and removing dt * v lowers its leave-one-out residual by at least this fraction.
CLOCK_IMPROVEMENT = 0.3


def clock_offsets(result: CalibrationResult, observations: WandObservations) -> tuple[ClockOffset, ...]:
    """Per camera timing error from leave-one-out residuals against image velocity.

    Each camera's points are compared with the projection of the wand
    triangulated from the other cameras; the image velocity is the central
    difference over the neighbouring frame ids (only frames whose ids are
    consecutive count).

    Args:
        result: the calibration (its cameras are matched by name).
        observations: the recording, frame ids in time order.
    """
    names = tuple(c.name for c in result.cameras)
    obs = observations.select_cameras(names)
    models = tuple(c.model for c in result.cameras)
    poses = tuple(c.pose for c in result.cameras)
    frames = obs.frames
    consecutive = np.zeros(frames.size, dtype=bool)
    consecutive[1:-1] = (frames[2:] - frames[:-2]) == 2
    # A few thousand frames are plenty for two numbers per camera.
    rows = np.flatnonzero(consecutive)
    rows = rows[spread_subset(rows.size, MAX_FRAMES)]
    uv = obs.uv[rows]
    velocity = (obs.uv[rows + 1] - obs.uv[rows - 1]) / 2.0
    bearings = np.stack([unproject(models[c], uv[:, c]) for c in range(len(names))], axis=2)  # (F, K, C, 3)
    rotations = np.stack([p.rotation for p in poses])
    translations = np.stack([p.translation for p in poses])
    out = []
    for c, name in enumerate(names):
        mine = np.flatnonzero(np.any(np.isfinite(uv[:, c, :, 0]), axis=1))  # the frames camera c sees
        others = bearings[mine].copy()
        others[:, :, c] = np.nan
        points = triangulate(others.reshape(-1, len(names), 3), rotations, translations).reshape(mine.size, -1, 3)
        residual = project(models[c], poses[c].apply(points)) - uv[mine, c]  # (F_c, K, 2)
        ok = np.all(np.isfinite(residual), axis=-1) & np.all(np.isfinite(velocity[mine, c]), axis=-1)
        r, v = residual[ok], velocity[mine, c][ok]
        if r.shape[0] < 10 or not np.any(v):
            continue
        offset = -float(np.sum(v * r) / np.sum(v * v))
        correlation = abs(float(np.sum(v * r) / np.sqrt(np.sum(v * v) * np.sum(r * r))))
        out.append(
            ClockOffset(
                name,
                offset,
                correlation,
                float(np.sqrt(np.mean(r**2))),
                float(np.sqrt(np.mean((r + offset * v) ** 2))),
                int(r.shape[0]),
            )
        )
    return tuple(out)


def clock_warnings(offsets: tuple[ClockOffset, ...]) -> list[str]:
    """Plain-language warnings for cameras whose residuals look like a clock offset."""
    return [
        f"{o.camera}: residuals follow the wand's image motion (correlation {o.correlation:.2f}): its clock seems "
        f"offset by {o.offset_frames:+.3f} frames; removing that would lower its residual from {o.rms_px:.2f} to "
        f"{o.rms_corrected_px:.2f} px. Check the camera synchronisation."
        for o in offsets
        if o.correlation >= CLOCK_CORRELATION and o.rms_corrected_px <= (1 - CLOCK_IMPROVEMENT) * o.rms_px
    ]
