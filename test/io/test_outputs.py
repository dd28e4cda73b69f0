"""Outputs are written as Unix tools write them: through a link to its target, a terminal or a pipe directly, new
files with the umask's permissions, an existing file's kept, and a failed write leaves nothing behind."""

from __future__ import annotations

import os
import socket
import stat
import threading
from pathlib import Path

import pytest

from wand_calib_ros.io.errors import OutputError
from wand_calib_ros.io.outputs import check_writable, is_special, umask, write_together


def test_a_symlinks_target_is_replaced_and_the_link_stays(tmp_path: Path) -> None:
    target = tmp_path / "elsewhere" / "result.yaml"
    target.parent.mkdir()
    target.write_text("old\n")
    link = tmp_path / "result.yaml"
    link.symlink_to(target)
    write_together({link: "new\n"})
    assert link.is_symlink() and os.readlink(link) == str(target)
    assert target.read_text() == "new\n"
    dangling = tmp_path / "dangling.yaml"
    dangling.symlink_to(tmp_path / "elsewhere" / "later.yaml")
    write_together({dangling: "made\n"})
    assert dangling.is_symlink() and (tmp_path / "elsewhere" / "later.yaml").read_text() == "made\n"


@pytest.mark.parametrize("mask", [0o022, 0o077, 0o002])
def test_new_files_follow_the_umask_and_existing_ones_keep_their_mode(tmp_path: Path, mask: int) -> None:
    before = os.umask(mask)
    try:
        assert umask() == mask
        write_together({tmp_path / "new.yaml": "a\n", tmp_path / "deep" / "er" / "new.png": b"\x89PNG"})
        assert stat.S_IMODE((tmp_path / "new.yaml").stat().st_mode) == 0o666 & ~mask
        assert stat.S_IMODE((tmp_path / "deep" / "er" / "new.png").stat().st_mode) == 0o666 & ~mask
        kept = tmp_path / "kept.yaml"
        kept.write_text("old\n")
        kept.chmod(0o640)
        write_together({kept: "new\n"})
        assert stat.S_IMODE(kept.stat().st_mode) == 0o640 and kept.read_text() == "new\n"
    finally:
        os.umask(before)


def test_a_pipe_or_a_device_is_written_directly_never_replaced(tmp_path: Path) -> None:
    read, write = os.pipe()
    try:
        stdout_like = Path(f"/proc/self/fd/{write}")  # what /dev/stdout is when the output is piped
        assert is_special(stdout_like)
        write_together({stdout_like: "through the pipe\n", tmp_path / "beside.yaml": "a file\n"})
        os.close(write)
        write = -1
        assert os.read(read, 100) == b"through the pipe\n"
        assert (tmp_path / "beside.yaml").read_text() == "a file\n"
    finally:
        os.close(read)
        if write >= 0:
            os.close(write)
    write_together({Path("/dev/null"): "nothing\n"})
    assert stat.S_ISCHR(Path("/dev/null").stat().st_mode)  # still the device
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    got: list[bytes] = []
    reader = threading.Thread(target=lambda: got.append(fifo.read_bytes()))
    reader.start()
    write_together({fifo: "to a reader\n"})
    reader.join(5)
    assert got == [b"to a reader\n"] and stat.S_ISFIFO(fifo.stat().st_mode)


def test_a_full_device_is_one_error_and_replaces_nothing(tmp_path: Path) -> None:
    result = tmp_path / "result.yaml"
    with pytest.raises(OutputError, match=r"cannot write /dev/full: No space left on device"):
        write_together({result: "staged\n", Path("/dev/full"): "to a full device\n"})
    assert not result.exists() and stat.S_ISCHR(Path("/dev/full").stat().st_mode)
    assert not list(tmp_path.iterdir())  # no temporary left


def test_a_failed_write_leaves_no_temporary_and_no_folder_it_made(tmp_path: Path, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    import tempfile

    def full_disk(*args: object, **kwargs: object) -> tuple[int, str]:  # the staged file on a full device
        return os.open("/dev/full", os.O_WRONLY), str(tmp_path / "staged.tmp")

    (tmp_path / "existing").mkdir()
    monkeypatch.setattr(tempfile, "mkstemp", full_disk)
    target = tmp_path / "existing" / "camera_info" / "deeper" / "cam0.yaml"
    with pytest.raises(OutputError, match="No space left on device"):
        write_together({target: "x\n"})
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["existing"]  # the folders it made are gone


def test_what_is_no_file_is_refused_in_one_line(tmp_path: Path) -> None:
    with pytest.raises(OutputError, match=r"it is a folder; give a file name"):
        check_writable([tmp_path])
    sock = socket.socket(socket.AF_UNIX)
    path = tmp_path / "s.sock"
    sock.bind(str(path))
    try:
        with pytest.raises(OutputError, match=r"is a socket; give a file name"):
            write_together({path: "x"})
    finally:
        sock.close()
    (tmp_path / "file").write_text("x")
    with pytest.raises(OutputError, match=r"is a file, not a folder"):
        check_writable([tmp_path / "file" / "result.yaml"])
    check_writable([tmp_path / "new" / "folders" / "result.yaml"])  # checked, not made
    assert not (tmp_path / "new").exists()
