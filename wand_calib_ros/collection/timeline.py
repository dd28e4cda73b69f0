"""Each camera's time line: where an image stands in time, decided once for the detector, the synchroniser and
the buffer.

From an image's header stamp and its arrival (the node's steady clock; None for a recording read from a file,
whose stamps are all there is), :meth:`TimeLines.place` decides

- its stamp on the camera's continuous time line. A camera's stamps should advance as its images arrive. When
  they do not (its driver restarted on a clock of its own, the host's clock was stepped, a bag was played again,
  a stamp leapt hours ahead), the stamps before and after cannot be compared: a *jump* starts a new segment of
  that camera's stamps, shifted to continue the old one on its frame grid (the time that passed, in whole frame
  periods, at least one): ``continuous = stamp + offset``. A jump is a stamp more than JUMP_S behind its
  camera's previous one, or more than that ahead of the time that passed between their arrivals. A *pause*
  (nothing arrives for a while, then the stamps go on where they were: a paused bag, a stalled driver or
  network) is no jump: its stamps are the truth. Cameras that jump by the same amount together (a clock step, a
  replay) get exactly the same shift, so frames stay frames. A camera whose stamps are zero (a driver that does
  not stamp) is stamped with its arrival, on the other cameras' time.
- its order: ``next`` (newer than every image of its camera placed so far), ``repeat`` (the same stamp again)
  or ``behind`` (older than one placed already). Only ``next`` images are searched, labelled, grouped into
  frames and stored; the others are counted here and nowhere else decides again. An image that cannot be
  used (another size, a truncated one) still has a true stamp and is placed like the others: a stretch of them
  is neither a pause nor a jump, and makes no good image after it late.

Gaps of more than DROP_GAP frame periods (and less than a silence, SILENCE_S) in a camera's stamps are counted
as dropped images.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

#: A stamp this far (s) from where its camera's previous stamp and the time between their arrivals put it
#: starts a new segment.
JUMP_S = 1.0
#: Cameras whose shifts differ by less than this (s) within SAME_JUMP_S of each other jumped together.
SAME_SHIFT_S = 0.1
SAME_JUMP_S = 5.0
#: Stamps a camera's frame period is learned from (for its dropped images).
PERIOD_WINDOW = 30
#: A gap of more than this many frame periods between consecutive stamps is images dropped ...
DROP_GAP = 1.5
#: ... up to this long (s); a longer one is the camera's silence (said as such by the node).
SILENCE_S = 1.0


@dataclass(frozen=True)
class StampJump:
    """A new segment of a camera's stamps.

    Attributes:
        camera: its name.
        kind: "back", "ahead" (its stamps against their arrivals) or "unstamped" (stamps of 0).
        jump_s: how far the stamps moved against the time between arrivals, s (0 for "unstamped").
        shared: another camera jumped by as much a moment ago (they share one shift: a clock step, a replay).
    """

    camera: str
    kind: str
    jump_s: float
    shared: bool = False

    def describe(self) -> str:
        """One line for the log."""
        if self.kind == "unstamped":
            return f"{self.camera}: its images are stamped 0 (its driver does not stamp them): using their arrivals"
        size = f"{abs(self.jump_s):.1f} s" if abs(self.jump_s) < 3600 else f"{abs(self.jump_s) / 3600:.1f} h"
        way = "back" if self.kind == "back" else "ahead"
        return (
            f"{self.camera}: its stamps jumped {size} {way} against the time between its images (a restarted "
            "driver, a clock step or a bag played again?): a new segment, its stamps shifted to continue; "
            "nothing is lost"
        )


#: Where an image stands against its camera's images placed before it.
Order = Literal["next", "repeat", "behind"]


@dataclass(frozen=True)
class Placed:
    """An image placed on its camera's time line.

    Attributes:
        stamp_ns: its stamp on the camera's continuous time line, ns (the header stamp where no jump shifted it).
        order: "next" (use it), "repeat" (its camera's newest stamp again) or "behind" (older than its newest).
        jump: the jump that started a new segment with it, if any.
    """

    stamp_ns: int
    order: Order
    jump: StampJump | None = None


@dataclass
class _Camera:
    stamp_ns: int | None = None  # its newest stamp as it came
    continuous_ns: int | None = None  # and continued
    arrival_ns: int = 0
    shift_ns: int = 0
    recent: deque[int] = field(default_factory=lambda: deque(maxlen=PERIOD_WINDOW))
    period_ns: float | None = None
    dropped: int = 0
    segments: int = 1
    unstamped: bool = False
    newest_ns: int | None = None  # its newest continuous stamp placed "next"
    behind: int = 0
    repeats: int = 0


class TimeLines:
    """The rig's cameras' time lines (see the module docstring)."""

    def __init__(self, cameras: tuple[str, ...]) -> None:
        self.cameras = cameras
        self._state = {name: _Camera() for name in cameras}
        self._recent_shifts: list[tuple[int, int]] = []  # (arrival ns, shift ns) of the latest jumps

    def place(self, camera: str, stamp_ns: int, arrival_ns: int | None) -> Placed:
        """Where a camera's image stands in time (see the module docstring).

        Args:
            camera: the camera.
            stamp_ns: its header stamp, ns.
            arrival_ns: when it arrived, on a steady clock (ns); None for a recording read from a file (its stamps
                are taken as they are: only their order is decided).
        """
        state = self._state[camera]
        continuous, jump = (
            (stamp_ns, None) if arrival_ns is None else self._continuous(state, camera, stamp_ns, arrival_ns)
        )
        if state.newest_ns is not None and continuous <= state.newest_ns:  # (it moves nothing: no drops, no pause)
            if continuous == state.newest_ns:
                state.repeats += 1
                return Placed(continuous, "repeat", jump)
            state.behind += 1
            return Placed(continuous, "behind", jump)
        self._count_drops(state, continuous)
        state.newest_ns = state.continuous_ns = continuous
        if arrival_ns is not None:
            state.stamp_ns, state.arrival_ns = continuous - state.shift_ns, arrival_ns
        return Placed(continuous, "next", jump)

    def restart(self) -> None:
        """A new take (/reset): every camera's time line starts again from its next image, its stamps taken as they
        are (nothing before is kept to continue)."""
        self._state = {name: _Camera() for name in self.cameras}
        self._recent_shifts = []

    def shift_ns(self, camera: str) -> int:
        """How far a camera's stamps are moved to continue its time line now (0: as they come)."""
        return self._state[camera].shift_ns

    def dropped(self, camera: str) -> int:
        """Images missing in a camera's stamps so far (gaps of more than DROP_GAP periods)."""
        return self._state[camera].dropped

    def segments(self, camera: str) -> int:
        """How many segments a camera's stamps came in (1: no jump)."""
        return self._state[camera].segments

    def values(self, camera: str) -> dict[str, int]:
        """Diagnostics counters of a camera's time line (drops, segments; images behind and repeated ones where
        there were any)."""
        state = self._state[camera]
        values = {"dropped": state.dropped, "stamp_segments": state.segments}
        if state.behind:
            values["out_of_order_images"] = state.behind
        if state.repeats:
            values["duplicate_stamps"] = state.repeats
        return values

    def totals(self) -> tuple[int, int]:
        """(images behind, repeated stamps) over the rig."""
        return sum(s.behind for s in self._state.values()), sum(s.repeats for s in self._state.values())

    def _continuous(self, state: _Camera, camera: str, stamp_ns: int, arrival_ns: int) -> tuple[int, StampJump | None]:
        """A camera's image's stamp continued (ns), and the jump that started a new segment with it, if any."""
        jump: StampJump | None = None
        if stamp_ns <= 0:
            if not state.unstamped:
                state.unstamped = True
                jump = StampJump(camera, "unstamped", 0.0)
            stamp_ns = self._rig_time(camera, arrival_ns) - state.shift_ns
        elif state.stamp_ns is not None and state.continuous_ns is not None:
            elapsed = arrival_ns - state.arrival_ns
            step = stamp_ns - state.stamp_ns
            expected = state.continuous_ns + elapsed
            off = stamp_ns + state.shift_ns - expected
            # back: its stamps went back beyond a reordering; ahead: they ran ahead of the time that passed. A pause
            # (nothing arrived for a while, the stamps then go on where they were: a paused bag, a stalled
            # driver) is neither: its stamps are the truth
            if step < -JUMP_S * 1e9 or step > elapsed + JUMP_S * 1e9:
                if state.period_ns is not None:  # on its own frame grid: the images between arrive in any rhythm
                    steps = max(round((expected - state.continuous_ns) / state.period_ns), 1)
                    expected = state.continuous_ns + round(steps * state.period_ns)
                shift, shared = self._shared_shift(expected - stamp_ns, arrival_ns)
                state.shift_ns, state.segments = shift, state.segments + 1
                state.recent.clear()
                jump = StampJump(camera, "back" if off < 0 else "ahead", off / 1e9, shared)
        return stamp_ns + state.shift_ns, jump

    def _rig_time(self, camera: str, arrival_ns: int) -> int:
        """The stamp an image arriving now would have on the other cameras' time (their newest stamp advanced
        by the time since it arrived); the arrival itself when no other camera has stamps."""
        times = [
            s.continuous_ns + arrival_ns - s.arrival_ns
            for name, s in self._state.items()
            if name != camera and s.continuous_ns is not None and not s.unstamped
        ]
        return max(times) if times else arrival_ns

    def _shared_shift(self, shift_ns: int, arrival_ns: int) -> tuple[int, bool]:
        """The shift of a jump, and whether it is another camera's of a moment ago (the same jump: a clock step)."""
        self._recent_shifts = [(t, s) for t, s in self._recent_shifts if arrival_ns - t <= SAME_JUMP_S * 1e9]
        for _, shift in self._recent_shifts:
            if abs(shift - shift_ns) <= SAME_SHIFT_S * 1e9:
                return shift, True
        self._recent_shifts.append((arrival_ns, shift_ns))
        return shift_ns, False

    @staticmethod
    def _count_drops(state: _Camera, continuous_ns: int) -> None:
        if state.continuous_ns is not None and state.period_ns is not None:
            gap_ns = continuous_ns - state.continuous_ns
            if DROP_GAP * state.period_ns < gap_ns <= SILENCE_S * 1e9:
                state.dropped += round(gap_ns / state.period_ns) - 1
        state.recent.append(continuous_ns)
        if len(state.recent) >= 3:  # the median step: exact for a steady stream, blind to a few gaps
            steps = np.diff(np.asarray(state.recent, dtype=np.int64))
            state.period_ns = float(np.median(steps[steps > 0])) if np.any(steps > 0) else None
