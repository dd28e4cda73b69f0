"""After a calibration, watch the rig for a camera that moved, off the node's executor.

The collector offers every frame it stores; once a second :meth:`BumpWatch.step` hands what came in to
one worker thread, which feeds a :class:`~wand_calib_ros.core.after.bumps.BumpMonitor` (levels from the
calibration's pixel noise) and keeps its verdict for /diagnostics and the log.
"""

from __future__ import annotations

import threading
from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.after.bumps import BumpMonitor, noise_levels
from wand_calib_ros.core.model.result import CalibrationResult
from wand_calib_ros.core.model.rig import RigSpec

FloatArray = NDArray[np.float64]

#: Frames kept waiting for the worker at most (the newest): a rig whose pairs take longer to judge
#: than the frames take to arrive (16 cameras: about 1 s of one core per second of frames, measured)
#: is judged on its latest frames instead of falling ever further behind.
MAX_PENDING = 300


class BumpWatch:
    """A calibrated rig watched frame by frame (see the module docstring)."""

    def __init__(self, rig: RigSpec, result: CalibrationResult) -> None:
        names = rig.camera_names
        models = tuple(result.camera(n).model for n in names)
        poses = tuple(result.camera(n).pose for n in names)
        levels = noise_levels(result.sigma_px, len(names))
        self.names = names
        self.monitor = BumpMonitor(names, models, poses, rig.wand, levels)
        self._pending: list[FloatArray] = []
        self._lock = threading.Lock()
        self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="bump watch")
        self._running: Future[None] | None = None
        self._lines: list[str] = []
        self._moved: tuple[str, ...] = ()

    def offer(self, uv: FloatArray) -> None:
        """One stored frame's (C, K, 2) pixels (cheap: only queued)."""
        if np.all(np.isfinite(uv), axis=(1, 2)).sum() >= 2:  # two whole views: some pair can judge it
            with self._lock:
                self._pending.append(uv)
                del self._pending[:-MAX_PENDING]

    def step(self) -> None:
        """Hand the queued frames to the worker unless it is still busy with the previous ones."""
        with self._lock:
            if not self._pending or (self._running is not None and not self._running.done()):
                return
            batch, self._pending = np.stack(self._pending), []
        self._running = self._worker.submit(self._judge, batch)

    def _judge(self, batch: FloatArray) -> None:
        self.monitor.add(batch)
        moved = tuple(self.names[c] for c in self.monitor.moved())
        lines = self.monitor.messages()
        with self._lock:
            self._moved, self._lines = moved, lines

    def moved(self) -> dict[str, str]:
        """The cameras judged to have moved, each with its message (``cam1 moved: residual ...``)."""
        with self._lock:
            return {name: line for name, line in zip(self._moved, self._lines, strict=False)}

    def close(self) -> None:
        """Stop the worker (a batch in progress is dropped)."""
        self._worker.shutdown(wait=False, cancel_futures=True)
