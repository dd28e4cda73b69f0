"""One writer per collection folder: a second collector on it refuses with one line.

The collector holds an exclusive ``flock`` on ``<output_dir>/.collector.lock`` (holding its process
id) for as long as it runs; the operating system releases it when the process ends, however it ends,
so a crashed collector never leaves the folder locked.
"""

from __future__ import annotations

import fcntl
import os
from pathlib import Path

from wand_calib_ros.collection.errors import CollectionError
from wand_calib_ros.io.outputs import check_writable

LOCK_FILE = ".collector.lock"


class CollectionLock:
    """The exclusive hold of a collection folder (see the module docstring)."""

    def __init__(self, folder: Path) -> None:
        """Take the folder (creating it).

        Raises:
            CollectionError: another collector holds it, naming its process, or the folder cannot be written.
            OutputError: a file stands where the folder should be.
        """
        self.path = folder / LOCK_FILE
        check_writable([self.path])  # (a file where the folder should be is named as such)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            folder.mkdir(parents=True, exist_ok=True)
            self._fd: int | None = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o666)
        except OSError as error:
            raise CollectionError(f"output_dir {folder}: cannot be written ({error.strerror})") from None
        try:
            fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            holder = os.pread(self._fd, 32, 0).decode(errors="replace").strip() or "another process"
            os.close(self._fd)
            self._fd = None
            raise CollectionError(
                f"output_dir {folder} is being written by another collector (process {holder}): stop it, or give "
                "this one its own output_dir"
            ) from None
        os.ftruncate(self._fd, 0)
        os.pwrite(self._fd, f"{os.getpid()}\n".encode(), 0)

    def release(self) -> None:
        """Let the folder go (at exit)."""
        if self._fd is not None:
            fcntl.flock(self._fd, fcntl.LOCK_UN)
            os.close(self._fd)
            self._fd = None
