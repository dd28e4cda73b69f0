"""A live rig's clocks that disagree by seconds: a camera's views held until the wand's motion lines its clock up.

A camera on a second computer, or one that stamps with its own clock, sends images whose stamps stand seconds
apart from the others' when they arrive. Grouped as they are, they would pair views of different instants (and
push the others' frames out). :class:`LiveClocks` notices such a camera by its stamps against their arrival (its
lead differs by more than SUSPECT_NS from the group of cameras that agree), holds its views (bounded: the last
TRACK_NS of them) and keeps every camera's recent views of the whole wand as tracks. Once the wand has moved through
its view and another's, the clock alignment of the calibration
(:func:`~wand_calib_ros.core.initialise.clock_alignment.find_clock_offsets`) finds its offset, which is said once;
from then on its views join the frames at their stamps less that offset. Views are stored with their own stamps,
so that the calibration of the buffer finds the same offset again and reports it whole.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.collection.stream_faults import Said
from wand_calib_ros.core.adjust.timing import frame_period
from wand_calib_ros.core.errors import TimingError
from wand_calib_ros.core.initialise.clock_alignment import MIN_OVERLAP_FRAMES, Track, find_clock_offsets
from wand_calib_ros.core.model.rig import RigSpec

FloatArray = NDArray[np.float64]

#: A camera whose stamps lead their arrival by more than this beyond the agreeing cameras' lead is held (ns): its
#: clock is another's (the frames' synchroniser waits this long for a late camera at most).
SUSPECT_NS = 500_000_000
#: Each camera's recent views kept as its track (ns).
TRACK_NS = 30_000_000_000
#: The clocks are looked at again at most this often while a camera is held (ns of arrival).
LOOK_NS = 1_000_000_000


@dataclass
class _Camera:
    lead_ns: int | None = None  # its newest image's stamp minus its arrival
    shift_ns: int | None = None  # its clock's offset once lined up (0: it agrees)
    held: int = 0  # views held so far
    track: deque[tuple[int, NDArray[np.float64]]] = field(default_factory=deque)


class LiveClocks:
    """The rig's cameras' clocks as their images arrive (see the module docstring)."""

    def __init__(self, rig: RigSpec) -> None:
        self.rig = rig
        self._cameras = {name: _Camera() for name in rig.camera_names}
        self._looked_ns: int | None = None
        self._said: set[str] = set()

    def arrived(self, camera: str, stamp_ns: int, arrival_ns: int) -> None:
        """An image of ``camera`` stamped ``stamp_ns`` (on its time line) arrived at ``arrival_ns``."""
        self._cameras[camera].lead_ns = stamp_ns - arrival_ns

    def restart(self) -> None:
        """A new take (/reset): the cameras' stamps against their arrival learned again from their next images (a
        replayed bag starts over); the offsets found stay (the cameras keep their clocks)."""
        for state in self._cameras.values():
            state.lead_ns = None
            state.track.clear()
        self._looked_ns = None

    def shift_ns(self, camera: str) -> int | None:
        """What to take off ``camera``'s stamps for the frames: its clock's offset (0 while nothing says it differs),
        or None: its views are held until its clock is lined up."""
        state = self._cameras[camera]
        if state.shift_ns is not None:
            return state.shift_ns
        return None if camera in self._suspects() else 0

    def keep(self, camera: str, stamp_ns: int, points: NDArray[np.float64] | None) -> None:
        """A labelled view of ``camera`` (its own stamp): kept in its track (the last TRACK_NS), counted if held."""
        state = self._cameras[camera]
        if state.shift_ns is None and camera in self._suspects():
            state.held += 1
        if points is None or not np.all(np.isfinite(points)):
            return
        state.track.append((stamp_ns, np.asarray(points, dtype=np.float64)))
        while state.track and state.track[0][0] < stamp_ns - TRACK_NS:
            state.track.popleft()

    def _suspects(self) -> set[str]:
        """The cameras whose lead differs by more than SUSPECT_NS from the largest group of agreeing ones (the first
        camera's group on a tie), their clocks not lined up yet."""
        leads = {n: s.lead_ns for n, s in self._cameras.items() if s.lead_ns is not None and s.shift_ns is None}
        placed = [
            s.lead_ns - s.shift_ns for s in self._cameras.values() if s.shift_ns is not None and s.lead_ns is not None
        ]
        if not leads:
            return set()
        candidates = list(leads.values()) + placed
        groups = [sum(abs(other - lead) <= SUSPECT_NS for other in candidates) for lead in candidates]
        reference = candidates[int(np.argmax(groups))]
        return {name for name, lead in leads.items() if abs(lead - reference) > SUSPECT_NS}

    def step(self, arrival_ns: int) -> list[Said]:
        """Look at the clocks again (at most every LOOK_NS while a camera is held): the held cameras' offsets found
        from the wand's motion where it decides them, said once. Returns what to say."""
        suspects = self._suspects()
        said = [
            Said(
                "warning",
                f"{name}: its stamps stand {self._apart_s(name):.1f} s from the other cameras' as they arrive: its "
                "clock is another's; its views are held until the wand, moving through its view and another "
                "camera's, lines its clock up",
            )
            for name in sorted(suspects)
            if self._first(f"held {name}")
        ]
        if not suspects or (self._looked_ns is not None and arrival_ns - self._looked_ns < LOOK_NS):
            return said
        self._looked_ns = arrival_ns
        tracks = tuple(self._track(name) for name in self.rig.camera_names)
        if any(tracks[self.rig.camera_names.index(name)].times.size < MIN_OVERLAP_FRAMES for name in suspects):
            return said
        try:
            apart = frozenset(self.rig.camera_names.index(name) for name in suspects)
            found = find_clock_offsets(self.rig, tracks, frames=False, apart=apart)
        except TimingError as error:
            return said + ([Said("warning", str(error))] if self._first(str(error)) else [])
        for c, name in enumerate(self.rig.camera_names):
            if name in suspects and found.moved[c]:
                self._cameras[name].shift_ns = round(float(found.offsets[c]) * 1e9)
        said += [Said("info", line) for line in found.lines if self._first(line)]
        return said

    def _apart_s(self, name: str) -> float:
        leads = [s.lead_ns for n, s in self._cameras.items() if n != name and s.lead_ns is not None]
        mine = self._cameras[name].lead_ns
        return 0.0 if mine is None or not leads else abs(mine - float(np.median(leads))) / 1e9

    def _track(self, name: str) -> Track:
        views = self._cameras[name].track
        times = np.array([stamp for stamp, _ in views], dtype=np.float64) / 1e9
        points = np.array([p for _, p in views], dtype=np.float64).reshape(-1, self.rig.wand.n_points, 2)
        period = frame_period(times)
        return Track(times, points, period if np.isfinite(period) else 1.0)

    def _first(self, key: str) -> bool:
        if key in self._said:
            return False
        self._said.add(key)
        return True

    def values(self, camera: str) -> dict[str, str]:
        """Diagnostics values of ``camera``'s clock: held (how many views so far), or its offset once found."""
        state = self._cameras[camera]
        if state.shift_ns:
            return {"clock_offset_s": f"{state.shift_ns / 1e9:+.3f}"}
        if state.shift_ns is None and camera in self._suspects():
            return {"clock": f"held until the wand lines it up ({state.held} views)"}
        return {}

    def stored_stamps(self, stamps_s: FloatArray) -> FloatArray:
        """(C,) a frame's stamps (s, on the lined-up clocks) as each camera stamped its image."""
        shift = np.array([(self._cameras[n].shift_ns or 0) / 1e9 for n in self.rig.camera_names])
        return np.asarray(stamps_s + shift, dtype=np.float64)
