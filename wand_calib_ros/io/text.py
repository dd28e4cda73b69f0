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
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise FormatError(path, f"not valid YAML: {error}") from None
