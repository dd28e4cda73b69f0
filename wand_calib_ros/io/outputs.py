"""Writing a calibration's files as a set: checked before the work, in place all together or not at all.

A calibration that fails to write its second file must not leave the first one behind looking
like a result; a path that cannot be written should be known before minutes of solving.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterable, Mapping
from pathlib import Path

from wand_calib_ros.io.errors import OutputError


def check_writable(paths: Iterable[str | Path]) -> None:
    """Create the folders of ``paths`` and check that each file can be written there.

    Raises:
        OutputError: naming the first path whose folder cannot be created (or is a file), that is a
            folder itself, or whose folder does not let this user write.
    """
    for path in map(Path, paths):
        if path.is_dir():
            raise OutputError(path, "it is a folder; give a file name")
        folder = path.parent
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except (FileExistsError, NotADirectoryError):
            raise OutputError(path, f"{_existing_file(folder)} is a file, not a folder") from None
        except OSError as error:
            raise OutputError(path, f"cannot create the folder {folder}: {error.strerror}") from None
        try:
            with tempfile.TemporaryFile(dir=folder):
                pass
        except OSError as error:
            raise OutputError(path, f"the folder {folder} does not take new files: {error.strerror}") from None
        if path.exists() and not os.access(path, os.W_OK):
            raise OutputError(path, "the existing file is read-only")


def write_together(documents: Mapping[Path, str]) -> None:
    """Write each text to its path: all to temporary siblings first, then each renamed into place.

    Raises:
        OutputError: a file could not be written; no output was replaced (the temporaries are removed).
    """
    staged: list[tuple[Path, Path]] = []
    current = next(iter(documents), Path())
    try:
        for path, text in documents.items():
            current = path
            check_writable([path])
            handle, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
            staged.append((Path(name), path))
            with os.fdopen(handle, "w", encoding="utf-8", newline="\n") as stream:
                stream.write(text)
        for temporary, path in staged:
            current = path
            os.replace(temporary, path)
    except OSError as error:
        raise OutputError(error.filename or current, error.strerror or str(error)) from None
    finally:
        for temporary, _ in staged:
            temporary.unlink(missing_ok=True)


def _existing_file(folder: Path) -> Path:
    """The file among ``folder`` and its parents that stands where a folder is needed."""
    for candidate in (folder, *folder.parents):
        if candidate.exists():
            return candidate
    return folder
