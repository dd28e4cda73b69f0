"""Reading the formats' text: one way to turn unreadable files, and cells that are not numbers, into a FormatError."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import yaml

from wand_calib_ros.io.errors import FormatError


def read_text(path: str | Path, kind: str) -> str:
    """The UTF-8 text at ``path`` (a byte-order mark allowed), ``kind`` naming what it should be ("a point file").

    Raises:
        FormatError: the file cannot be read or is not UTF-8 text (a binary file).
    """
    path = Path(path)
    try:
        return path.read_text(encoding="utf-8-sig")
    except OSError as error:
        raise FormatError(path, f"cannot read: {error.strerror}") from None
    except UnicodeDecodeError as error:
        byte = error.object[error.start]
        raise FormatError(path, f"not UTF-8 text (it holds the byte 0x{byte:02x}): not {kind}?") from None


def finite_number(path: Path, row: int, cell: str, meaning: str, column: str | None = None, hint: str = "") -> float:
    """A table cell's finite number: ``meaning`` says what it is ("a pixel coordinate"), ``column`` names its
    column, if the table has names, ``hint`` ends the message of a cell that is no number.

    Raises:
        FormatError: naming the file, the row, the column and the cell.
    """
    text = cell.strip()
    name = f"{column} {text!r}" if column else repr(text)
    try:
        value = float(text)
    except ValueError:
        raise FormatError(path, f"{name} is not a number{hint}", row=row) from None
    if not math.isfinite(value):
        raise FormatError(path, f"{name} is not {meaning}", row=row)
    return value


#: PyYAML's safe loader, libyaml's where PyYAML was built with it (the same documents, 10x faster: a 64-camera
#: rig's cameras.yaml in 2 instead of 20 ms).
_SAFE_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


def read_yaml(path: str | Path) -> Any:
    """The YAML document at ``path`` (UTF-8, a byte-order mark allowed).

    Raises:
        FormatError: the file cannot be read, is not UTF-8 text (a binary file) or not YAML.
    """
    path = Path(path)
    text = read_text(path, "a YAML file")
    if text.startswith("%YAML:1.0"):  # cv2.FileStorage's header, which PyYAML refuses
        raise FormatError(path, "an OpenCV FileStorage file, not a wand_calib_ros result or ROS YAML file")
    try:
        return yaml.load(text, Loader=_SAFE_LOADER)
    except yaml.YAMLError as error:
        raise FormatError(path, f"not valid YAML: {_one_line(error)}{_looks_like(text)}") from None


def _one_line(error: yaml.YAMLError) -> str:
    """PyYAML's message (several lines, with a quote of the file) as one line: what, and where."""
    problem = getattr(error, "problem", None) or getattr(error, "context", None) or "cannot be parsed"
    mark = getattr(error, "problem_mark", None) or getattr(error, "context_mark", None)
    where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
    return f"{problem}{where}"


def _looks_like(text: str) -> str:
    """A hint at what a text that is not YAML may be instead ('' when nothing in it says)."""
    lines = [line.strip() for line in text.splitlines() if line.strip() and not line.lstrip().startswith("#")]
    if lines and lines[0].startswith("[") and lines[0].endswith("]") and any(" = " in line for line in lines):
        return " (a TOML file? give the result YAML wand-calib wrote)"
    return ""
