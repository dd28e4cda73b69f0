"""The command's allocator settings: a large array served from malloc's heap, not a mapping of its own."""

from __future__ import annotations

import ctypes
import subprocess
import sys

import pytest

#: In a fresh interpreter: the bytes a 64 MB array adds to those glibc holds in mappings of their own (mallinfo2's
#: hblkhd), with or without the settings first.
PROBE = """
import ctypes, sys
import numpy as np
from wand_calib_ros.memory import keep_freed_memory

class Info(ctypes.Structure):
    names = "arena ordblks smblks hblks hblkhd usmblks fsmblks uordblks fordblks keepcost"
    _fields_ = [(name, ctypes.c_size_t) for name in names.split()]

libc = ctypes.CDLL(None)
libc.mallinfo2.restype = Info
took = keep_freed_memory() if sys.argv[1] == "keep" else None
before = libc.mallinfo2().hblkhd
array = np.ones(8_000_000)
print(took, libc.mallinfo2().hblkhd - before)
"""


def _glibc_with_mallinfo2() -> bool:
    try:
        return hasattr(ctypes.CDLL(None), "mallinfo2")
    except OSError:
        return False


@pytest.mark.skipif(not sys.platform.startswith("linux") or not _glibc_with_mallinfo2(), reason="glibc 2.33+ only")
def test_large_arrays_come_from_the_heap_once_freed_memory_is_kept() -> None:
    def mapped(mode: str) -> tuple[str, int]:
        out = subprocess.run([sys.executable, "-c", PROBE, mode], capture_output=True, text=True, check=True).stdout
        took, held = out.split()
        return took, int(held)

    assert mapped("default")[1] >= 64_000_000  # without the settings the array is a mapping of its own
    assert mapped("keep") == ("True", 0)
