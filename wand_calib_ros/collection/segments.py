"""A live camera's stamps made continuous: restarted drivers, clock steps, replayed bags, unstamped images.

A camera's header stamps should advance as its images arrive. When they do not (its driver restarted
on a clock of its own, the host's clock was stepped, a bag was played again, a stamp leapt hours
ahead), the stamps before and after cannot be compared, and a synchroniser that trusts them drops
every image after the jump as out of order or lets one camera's leap push the others' frames out.
:class:`StampSegments` notices such a jump by comparing each image's stamp with its camera's
previous one and the time between their arrivals (the node's steady clock), and starts a
new *segment* of that camera's stamps, shifted to continue the old one on its frame grid (that
time in whole frame periods, at least one): ``continuous = stamp + offset``. A jump is a stamp more than
JUMP_S behind its camera's previous one, or more than that ahead of the time that passed between their
arrivals; a pause (nothing arrives for a while, then the stamps go on where they were: a paused bag, a
stalled driver or network) is no jump, and its stamps stay as they are. Cameras that jump by
the same amount together (a clock step, a replay) get exactly the same shift, so frames stay
frames. A camera whose stamps are zero (a driver that does not stamp) is stamped with its arrival,
on the other cameras' time. Gaps of more than DROP_GAP frame periods (and less than a silence,
SILENCE_S) in a camera's stamps are counted as dropped images.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

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


class StampSegments:
    """Per camera, its stamps continued across jumps (see the module docstring)."""

    def __init__(self, cameras: tuple[str, ...]) -> None:
        self.cameras = cameras
        self._state = {name: _Camera() for name in cameras}
        self._recent_shifts: list[tuple[int, int]] = []  # (arrival ns, shift ns) of the latest jumps

    def continuous(self, camera: str, stamp_ns: int, arrival_ns: int) -> tuple[int, StampJump | None]:
        """A camera's image's stamp continued (ns), and the jump that started a new segment with it, if any.

        Args:
            camera: the camera.
            stamp_ns: its header stamp.
            arrival_ns: when it arrived, on a steady clock (ns).
        """
        state = self._state[camera]
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
        continuous = stamp_ns + state.shift_ns
        self._count_drops(state, continuous)
        state.stamp_ns, state.continuous_ns, state.arrival_ns = stamp_ns, continuous, arrival_ns
        return continuous, jump

    def dropped(self, camera: str) -> int:
        """Images missing in a camera's stamps so far (gaps of more than DROP_GAP periods)."""
        return self._state[camera].dropped

    def segments(self, camera: str) -> int:
        """How many segments a camera's stamps came in (1: no jump)."""
        return self._state[camera].segments

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
