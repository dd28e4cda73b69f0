"""Live floor frames: the wand laid still on the floor while ``/set_floor`` holds a window open.

Each ``/set_floor`` call opens a window of ``hold_s`` seconds; the frames the buffer stores while
it is open are floor frames (stored even though the wand is still) and their ids are appended to
``FLOOR_FILE`` next to the buffer, one per line. ``/calibrate`` reads that file and fits the world
frame to those frames (:mod:`wand_calib_ros.core.after.world_frame`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from wand_calib_ros.io.errors import FormatError

#: The floor frames' file in a collector's output directory.
FLOOR_FILE = "floor_frames.txt"


@dataclass
class FloorWindow:
    """When frames are floor frames: between a ``/set_floor`` call and ``hold_s`` later (monotonic s)."""

    hold_s: float
    until: float = float("-inf")
    lays: int = 0

    def open(self, now: float) -> int:
        """Start a lay of the wand on the floor; returns its number (1 for the first)."""
        self.until = now + self.hold_s
        self.lays += 1
        return self.lays

    def is_open(self, now: float) -> bool:
        return now <= self.until


def append_floor_frame(path: Path, frame: int) -> None:
    """Add one frame id to the floor file (created when missing; flushed at once)."""
    with path.open("a", encoding="utf-8", newline="\n") as handle:
        handle.write(f"{frame}\n")


def read_floor_frames(path: Path) -> tuple[int, ...]:
    """The frame ids of a floor file (empty when there is none).

    Raises:
        FormatError: a line that is not a frame id (naming the file and line), or a file that is not text.
    """
    if not path.exists():
        return ()
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise FormatError(path, "not UTF-8 text: not a floor_frames.txt (one frame id per line)") from None
    frames = []
    for number, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        try:
            frames.append(int(line))
        except ValueError:
            raise FormatError(path, f"expected a frame id, got {line!r}", row=number) from None
    return tuple(sorted(set(frames)))
