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

from wand_calib_ros.core.camera_model import project
from wand_calib_ros.core.refine import triangulate_placements
from wand_calib_ros.core.result import CalibrationResult, ClockOffset
from wand_calib_ros.core.rig import WandObservations

FloatArray = NDArray[np.float64]

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
    out = []
    for c, name in enumerate(names):
        others = obs.uv.copy()
        others[:, c] = np.nan
        points = triangulate_placements(models, poses, others)
        residual = project(models[c], poses[c].apply(points)) - obs.uv[:, c]  # (F, 3, 2)
        velocity = np.full_like(residual, np.nan)
        velocity[1:-1] = (obs.uv[2:, c] - obs.uv[:-2, c]) / 2.0
        ok = np.all(np.isfinite(residual), axis=-1) & np.all(np.isfinite(velocity), axis=-1) & consecutive[:, None]
        r, v = residual[ok], velocity[ok]
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
