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

from wand_calib_ros.core.model.camera_model import project, unproject
from wand_calib_ros.core.model.geometry import ray_sums, ray_terms, solve_ray_sums
from wand_calib_ros.core.model.result import CalibrationResult, ClockOffset
from wand_calib_ros.core.model.rig import WandObservations, spread_subset

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
    n_frames, n_cameras, n_markers = uv.shape[:3]
    # Every marker's rays, summed once; each camera's leave-one-out point drops its own ray's terms.
    seen = [np.nonzero(np.isfinite(uv[:, c, :, 0]) & np.isfinite(uv[:, c, :, 1])) for c in range(n_cameras)]
    point = [frame * n_markers + marker for frame, marker in seen]
    rays = [unproject(models[c], uv[frame, c, marker]) @ poses[c].rotation for c, (frame, marker) in enumerate(seen)]
    centres = [np.broadcast_to(p.center, (r.shape[0], 3)) for p, r in zip(poses, rays, strict=True)]
    count, lhs, rhs = ray_sums(
        np.concatenate(point), n_frames * n_markers, np.concatenate(rays), np.concatenate(centres)
    )
    out = []
    for c, name in enumerate(names):
        mine = np.flatnonzero(np.any(np.isfinite(uv[:, c, :, 0]), axis=1))  # the frames camera c sees
        own_lhs, own_rhs = ray_terms(rays[c], centres[c])
        others = count.copy(), lhs.copy(), rhs.copy()
        others[0][point[c]] -= 1.0
        others[1][point[c]] -= own_lhs
        others[2][point[c]] -= own_rhs
        points = solve_ray_sums(*others).reshape(n_frames, n_markers, 3)[mine]
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
