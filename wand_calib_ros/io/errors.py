"""Errors of the file formats."""

from __future__ import annotations

from pathlib import Path

from wand_calib_ros.errors import WandCalibError


class FormatError(WandCalibError):
    """A file that does not follow its format; the message names the file and where."""

    def __init__(self, path: str | Path, message: str, *, row: int | None = None) -> None:
        where = f"{path}" if row is None else f"{path}, row {row}"
        super().__init__(f"{where}: {message}")
        self.path = Path(path)
        self.row = row


class OutputError(WandCalibError):
    """An output that cannot be written; the message names the path and why."""

    def __init__(self, path: str | Path, reason: str) -> None:
        super().__init__(f"cannot write {path}: {reason}")
        self.path = Path(path)


class ExportError(WandCalibError):
    """A calibration that a format cannot express (e.g. a fisheye as DLT coefficients); the message
    names the camera and why."""
