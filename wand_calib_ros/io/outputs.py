"""Writing a command's or a node's files as Unix tools write them, as a set: checked before the work, in place all
together or not at all.

A calibration that fails to write its second file must not leave the first one behind looking like a result; a
path that cannot be written should be known before minutes of solving. Each path is written where it leads:

- a symbolic link's target is written (the link stays, pointing at the new file);
- a regular file, or a new one, is written to a temporary sibling and renamed over it (a reader never sees half a
  file); an existing file keeps its permissions, a new one takes the user's umask (0644 under 022: a driver
  running as another user reads it);
- a terminal, a pipe or another character device (``/dev/stdout``, ``/proc/self/fd/1``, ``/dev/null``) is written
  directly, after everything else is staged, and never replaced; a socket, a block device or a folder is refused
  with one line;
- a failed write replaces nothing and leaves nothing behind: no temporary file, and no folder it created.
"""

from __future__ import annotations

import contextlib
import os
import stat
import tempfile
from collections.abc import Iterable, Mapping
from pathlib import Path

from wand_calib_ros.io.errors import OutputError

#: What a new file's permissions start from before the umask (read and write for everybody, as ``touch`` makes).
NEW_FILE_MODE = 0o666


def check_writable(paths: Iterable[str | Path]) -> None:
    """Check that each path can be written (nothing is created).

    Raises:
        OutputError: naming the first path that is a folder or a socket, whose folder would be a file, that this
            user may not write (its folder, or the existing read-only file), or whose folder does not take new files.
    """
    for path in map(Path, paths):
        target = _target(path)
        if target.is_dir():
            raise OutputError(path, "it is a folder; give a file name")
        if target.exists() and not target.is_file():
            _direct_kind(path, target)  # (raises for what cannot be written directly)
            if not os.access(target, os.W_OK):
                raise OutputError(path, "this user may not write it")
            continue
        folder = _existing_ancestor(target.parent)
        if not folder.is_dir():
            raise OutputError(path, f"{folder} is a file, not a folder")
        if folder == target.parent:
            try:
                with tempfile.TemporaryFile(dir=folder):
                    pass
            except OSError as error:
                raise OutputError(path, f"the folder {folder} does not take new files: {error.strerror}") from None
        elif not os.access(folder, os.W_OK | os.X_OK):
            raise OutputError(path, f"cannot create the folder {target.parent}: {folder} does not take new folders")
        if target.exists() and not os.access(target, os.W_OK):
            raise OutputError(path, "the existing file is read-only")


def write_together(documents: Mapping[Path, str | bytes]) -> None:
    """Write each text (UTF-8, LF) or bytes to its path, all or none (see the module docstring).

    Raises:
        OutputError: naming the output that could not be written and why; nothing was replaced.
    """
    staged: list[tuple[Path, Path]] = []  # (temporary, target)
    direct: list[tuple[Path, Path, str | bytes]] = []  # (path, special file, content)
    created: list[Path] = []
    current = next(iter(documents), Path())
    try:
        for path, content in documents.items():
            current = path
            check_writable([path])
            target = _target(path)
            if target.exists() and not target.is_file():
                direct.append((path, target, content))
                continue
            _make_folders(target.parent, created)
            mode = stat.S_IMODE(target.stat().st_mode) if target.exists() else NEW_FILE_MODE & ~umask()
            handle, name = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
            staged.append((Path(name), target))
            with os.fdopen(handle, "wb") as stream:
                stream.write(content.encode("utf-8") if isinstance(content, str) else content)
                stream.flush()
                if stat.S_ISREG(os.fstat(stream.fileno()).st_mode):  # (mkstemp made it 0600)
                    os.fchmod(stream.fileno(), mode)
        for path, target, content in direct:  # (a terminal or a pipe cannot be rolled back: after the staging)
            current = path
            with target.open("wb") as stream:
                stream.write(content.encode("utf-8") if isinstance(content, str) else content)
        for temporary, target in staged:
            current = target
            os.replace(temporary, target)
    except OSError as error:
        for temporary, _ in staged:
            temporary.unlink(missing_ok=True)
        for folder in reversed(created):
            _remove_if_empty(folder)
        raise OutputError(current, error.strerror or str(error)) from None
    finally:
        for temporary, _ in staged:
            temporary.unlink(missing_ok=True)


def write_text(path: str | Path, content: str | bytes) -> None:
    """:func:`write_together` of one file."""
    write_together({Path(path): content})


def is_special(path: str | Path) -> bool:
    """Whether writing ``path`` writes a terminal, a pipe or another special file (not a regular file's place)."""
    target = _target(Path(path))
    return target.exists() and not target.is_file() and not target.is_dir()


def umask() -> int:
    """This process's umask, read without changing it (Linux's /proc; elsewhere set and restored at once)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _target(path: Path) -> Path:
    """Where writing ``path`` leads: a symbolic link's final target (a dangling one's too), else the path; a link to
    a device or a pipe stays itself (``/proc/self/fd/1`` names a pipe no path resolves to: written through it)."""
    if not path.is_symlink():
        return path
    try:
        mode = path.stat().st_mode  # (follows the links)
    except OSError:
        return Path(os.path.realpath(path))
    return Path(os.path.realpath(path)) if stat.S_ISREG(mode) or stat.S_ISDIR(mode) else path


def _direct_kind(path: Path, target: Path) -> str:
    """What kind of special file ``target`` is, when it can be written directly (a character device: a terminal,
    /dev/null; a pipe).

    Raises:
        OutputError: a socket, a block device or anything else that is no file to write.
    """
    mode = target.stat().st_mode
    if stat.S_ISCHR(mode):
        return "device"
    if stat.S_ISFIFO(mode):
        return "pipe"
    kind = "a socket" if stat.S_ISSOCK(mode) else "a block device" if stat.S_ISBLK(mode) else "not a file"
    raise OutputError(path, f"{target} is {kind}; give a file name")


def _existing_ancestor(folder: Path) -> Path:
    """``folder`` or its nearest ancestor that exists (as a file or a folder)."""
    for candidate in (folder, *folder.parents):
        if candidate.exists():
            return candidate
    return folder


def _make_folders(folder: Path, created: list[Path]) -> None:
    """Create ``folder`` and its missing parents, outermost first, each added to ``created`` once made."""
    for missing in [f for f in (folder, *folder.parents) if not f.exists()][::-1]:
        missing.mkdir()
        created.append(missing)


def _remove_if_empty(folder: Path) -> None:
    with contextlib.suppress(OSError):
        folder.rmdir()
