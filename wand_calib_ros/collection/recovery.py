"""Keeping a persisted buffer whole across crashes and resets.

The buffer is appended one frame at a time. A process killed (or a machine losing power) in the
middle of an append leaves a torn tail: a last line without its newline, sometimes NUL padding
after it. :func:`cut_torn_tail` cuts the file back to the last complete frame and keeps the
original aside; :func:`backup_path` names backups so that no backup ever replaces another, and
:func:`move_aside` moves a file to one (through a symbolic link: its target's content, the link kept).
"""

from __future__ import annotations

import os
import shutil
import time
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class TornTail:
    """What :func:`cut_torn_tail` cut: the frame whose rows were dropped and where the original is."""

    original: Path  #: a copy of the file as found
    dropped_rows: int  #: complete rows of the torn frame, plus the torn line itself
    frame: int | None  #: the torn frame's id (None when the tear cut its id)

    def describe(self, path: Path) -> str:
        """One line for the log."""
        if not self.dropped_rows:
            return f"{path}: NUL padding after the last row removed; the file as found is kept as {self.original}"
        frame = "a frame whose id was cut" if self.frame is None else f"frame {self.frame}"
        return (
            f"{path}: the last write was torn (the process stopped mid-row): {frame} cut "
            f"({self.dropped_rows} rows); the file as found is kept as {self.original}"
        )


def backup_path(path: Path, kind: str) -> Path:
    """A new, unused sibling name for a copy of ``path``: ``<stem>.<YYYYmmdd-HHMMSS>[-n].<kind><suffix>``.

    The name is created (empty) before it is returned, so two callers in the same second get two
    names and a later move onto it replaces only this placeholder.
    """
    stamp = time.strftime("%Y%m%d-%H%M%S")
    for n in range(1, 10_000):
        tag = stamp if n == 1 else f"{stamp}-{n}"
        candidate = path.with_name(f"{path.stem}.{tag}.{kind}{path.suffix}")
        try:
            with candidate.open("xb"):
                return candidate
        except FileExistsError:
            continue
    raise FileExistsError(f"{path}: no free backup name for {stamp}")


def move_aside(path: Path, kind: str) -> Path:
    """Move the file at ``path`` to a new backup beside it (:func:`backup_path`) and return the backup.

    A regular file is renamed (its permissions go with it). Through a symbolic link the link stays where
    the user put it: its target's content is copied to the backup and the target emptied, to be written
    again through the link.
    """
    backup = backup_path(path, kind)
    if not path.is_symlink():
        os.replace(path, backup)
        return backup
    shutil.copyfile(path, backup)
    with path.open("r+b") as handle:
        handle.truncate(0)
        os.fsync(handle.fileno())
    return backup


def cut_torn_tail(path: Path) -> TornTail | None:
    """Cut a torn last write off the CSV at ``path``; None when its last line is complete.

    A tail is torn when the file does not end with a newline (after any NUL padding a crash left).
    The torn line and the complete rows of the same frame before it are removed (the frame was
    being written), so the file ends with the last complete frame and the next append starts on a
    new line. A tear within a row's frame id cuts that row only (whose frame it was cannot be
    told). The file as found is copied aside first.
    """
    data = path.read_bytes()
    end = len(data.rstrip(b"\x00"))
    if end == len(data) and (end == 0 or data.endswith(b"\n")):
        return None
    cut = data.rfind(b"\n", 0, end) + 1
    frame, dropped = None, 0
    if cut < end:  # a partial row (else only padding after a complete one)
        lines = data[:cut].splitlines(keepends=True)
        frame = _frame_of(data[cut:end], complete=False)  # None: the tear cut the id (a frame's first row)
        dropped = 1
        while len(lines) > 1 and frame is not None and _frame_of(lines[-1]) == frame:
            cut -= len(lines.pop())
            dropped += 1
    original = backup_path(path, "torn")
    shutil.copyfile(path, original)
    with path.open("r+b") as handle:
        handle.truncate(cut)
        handle.flush()
        os.fsync(handle.fileno())
    return TornTail(original, dropped, frame)


def _frame_of(line: bytes, *, complete: bool = True) -> int | None:
    """The frame id a CSV row starts with (None: none; a torn row's id counts only when a comma ends it)."""
    head, comma, _ = line.partition(b",")
    if not comma and not complete:
        return None
    try:
        return int(head)
    except ValueError:
        return None
