"""The running estimate: while the wand is waved, the buffer so far is calibrated every few seconds.

Each round calibrates at most :data:`MAX_PLACEMENTS` placements spread over the buffer (a time bound),
warm-started from the previous round's cameras (its pairwise initialisation skipped), in one worker
process of its own at the lowest CPU priority (:mod:`~wand_calib_ros.collection.estimate_worker`): the
node's detection never waits for it, not even for the interpreter's lock. The
first round starts once the buffer holds :data:`MIN_FRAMES` frames showing the whole wand to two
cameras, and none starts on a buffer that has not grown since the newest result; a round that fails
(the rig not connected yet, too few views) says why and the next one starts cold. Each finished
round is an :class:`Estimate`: the result with its quality verdict, the scene for RViz, and per
camera whether its uncertainties still fall.
"""

from __future__ import annotations

import multiprocessing
import threading
from collections.abc import Callable
from dataclasses import dataclass, replace
from multiprocessing.connection import Connection
from multiprocessing.process import BaseProcess

import numpy as np

from wand_calib_ros.collection.estimate_round import Round
from wand_calib_ros.collection.estimate_worker import serve
from wand_calib_ros.core.model.result import CalibrationResult
from wand_calib_ros.core.model.rig import RigSpec, WandObservations, spread_subset
from wand_calib_ros.core.pipeline import CalibrationOptions

#: Placements one round calibrates at most (about 0.3 s for 3 cameras, 2 s for 16, measured here).
MAX_PLACEMENTS = 400
#: Frames showing the whole wand to two cameras before the first round.
MIN_FRAMES = 30
#: An uncertainty still falls when it dropped by more than this fraction since the previous round.
IMPROVING = 0.05


@dataclass(frozen=True, eq=False)
class Estimate:
    """The newest finished round and how it compares with the one before.

    Attributes:
        round: the round.
        finished: when it arrived (time.monotonic()).
        improving: per camera name whether its focal or principal-point uncertainty still falls
            (True for a first result).
    """

    round: Round
    finished: float
    improving: dict[str, bool]


def round_input(rig: RigSpec, observations: WandObservations, max_placements: int) -> WandObservations | None:
    """The frames one round calibrates: those showing the whole wand to two cameras, at most
    ``max_placements`` spread over the take (None: fewer than :data:`MIN_FRAMES`)."""
    usable = np.flatnonzero(observations.complete.sum(axis=1) >= 2)
    if usable.size < MIN_FRAMES:
        return None
    if usable.size > max_placements:
        usable = usable[spread_subset(usable.size, max_placements)]
    return observations.select_frames(usable)


def still_improving(previous: CalibrationResult | None, result: CalibrationResult) -> dict[str, bool]:
    """Per camera whether its focal or principal-point standard deviation fell by more than
    :data:`IMPROVING` since ``previous`` (all True without one)."""
    names = [c.name for c in result.cameras]
    if previous is None or previous.quality is None or result.quality is None:
        return dict.fromkeys(names, True)
    before = {c.name: c for c in previous.quality.cameras}
    out = {}
    for camera in result.quality.cameras:
        old = before.get(camera.name)
        out[camera.name] = old is None or (
            camera.focal_std_percent < (1 - IMPROVING) * old.focal_std_percent
            or camera.principal_std_px < (1 - IMPROVING) * old.principal_std_px
        )
    return out


def converged(result: CalibrationResult, focal_std_percent: float, principal_std_px: float) -> bool:
    """Whether every camera's focal-length (% of it) and principal-point (px) standard deviations are
    at most these (auto_calibrate's condition besides coverage)."""
    if result.quality is None:
        return False
    return all(
        c.focal_std_percent <= focal_std_percent and c.principal_std_px <= principal_std_px
        for c in result.quality.cameras
    )


class RunningEstimate:
    """Rounds of calibration on a worker process, stepped by the node's 1 Hz timer (module docstring)."""

    def __init__(
        self,
        rig: RigSpec,
        options: CalibrationOptions,
        *,
        period_s: float = 3.0,
        max_placements: int = MAX_PLACEMENTS,
    ) -> None:
        self.rig = rig
        self.options = replace(options, floor_frames=())
        self.period_s = period_s
        self.max_placements = max_placements
        self.latest: Estimate | None = None  # the newest round that gave a result
        self.failure: str | None = None  # why the newest round gave none
        self._connection: Connection | None = None
        self._process: BaseProcess | None = None
        self._busy = False
        self._started = -float("inf")
        self._lock = threading.Lock()  # step() on the node's executor, close() from its shutdown
        self._closed = False

    def _start_worker(self) -> Connection:
        if self._connection is None:
            context = multiprocessing.get_context("spawn")  # no fork of a process with DDS threads
            ours, theirs = context.Pipe()
            process = context.Process(target=serve, args=(theirs,), name="wand_calib running estimate", daemon=True)
            process.start()
            theirs.close()
            self._connection, self._process = ours, process
        return self._connection

    def step(self, now: float, snapshot: Callable[[], WandObservations]) -> Estimate | None:
        """Collect a finished round (returned when it gave a result) and start the next one when due.

        Args:
            now: time.monotonic().
            snapshot: the buffer so far (called only when a round starts).
        """
        with self._lock:
            if self._closed:
                return None
            return self._step(now, snapshot)

    def _step(self, now: float, snapshot: Callable[[], WandObservations]) -> Estimate | None:
        arrived = None
        try:
            done = self._finished()
        except (EOFError, OSError):  # the worker died (killed, out of memory): the next round starts a new one
            self._stop_worker()
            self.failure = "the running estimate's worker process stopped; starting a new one"
            done = None
        if done is not None:
            if done.result is None:
                self.failure = done.failure
            else:
                previous = self.latest.round.result if self.latest is not None else None
                arrived = Estimate(done, now, still_improving(previous, done.result))
                self.latest, self.failure = arrived, None
        if not self._busy and now - self._started >= self.period_s:
            observations = snapshot()
            frames = int(observations.frames.size)
            # A buffer that has not grown since the newest result (the wand at rest, waving over, a
            # /calibrate running) has nothing new to estimate: no round takes the CPU from the node.
            settled = self.latest is not None and self.failure is None and self.latest.round.frames == frames
            chosen = None if settled else round_input(self.rig, observations, self.max_placements)
            if chosen is not None:
                warm = self.latest.round.result if self.latest is not None and self.failure is None else None
                options = replace(self.options, start=warm)
                try:
                    self._start_worker().send((self.rig, chosen, options, frames))
                    self._busy = True
                except OSError:  # a broken pipe: the worker died between rounds
                    self._stop_worker()
                self._started = now
        return arrived

    def _finished(self) -> Round | None:
        """The round the worker finished, if any (EOFError, OSError: it died)."""
        if not self._busy or self._connection is None or not self._connection.poll():
            return None
        done: Round = self._connection.recv()
        self._busy = False
        return done

    def restart(self) -> None:
        """Forget every round (a new buffer): the worker stops, the next round starts cold."""
        with self._lock:
            self._stop_worker()
            self.latest = self.failure = None
            self._started = -float("inf")

    def close(self) -> None:
        """Stop the worker process for good (a round in progress is dropped)."""
        with self._lock:
            self._closed = True
            self._stop_worker()

    def _stop_worker(self) -> None:
        if self._connection is not None:
            try:
                if not self._busy:
                    self._connection.send(None)
            except OSError:
                pass
            self._connection.close()
        if self._process is not None:
            self._process.join(timeout=1.0)
            if self._process.is_alive():
                self._process.terminate()
                self._process.join(timeout=5.0)
        self._connection = self._process = None
        self._busy = False
