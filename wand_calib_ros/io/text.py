"""Reading the YAML documents of the formats: one way to turn unreadable files into a FormatError."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from wand_calib_ros.io.errors import FormatError


def read_yaml(path: str | Path) -> Any:
    """The YAML document at ``path`` (UTF-8, a byte-order mark allowed).

    Raises:
        FormatError: the file cannot be read, is not UTF-8 text (a binary file) or not YAML.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except OSError as error:
        raise FormatError(path, f"cannot read: {error.strerror}") from None
    except UnicodeDecodeError as error:
        byte = error.object[error.start]
        raise FormatError(path, f"not UTF-8 text (it holds the byte 0x{byte:02x}): not a YAML file?") from None
    if text.startswith("%YAML:1.0"):  # cv2.FileStorage's header, which PyYAML refuses
        raise FormatError(path, "an OpenCV FileStorage file, not a wand_calib_ros result or ROS YAML file")
    try:
        return yaml.safe_load(text)
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
