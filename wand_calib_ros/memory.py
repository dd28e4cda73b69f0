"""The process's memory: freed arrays kept for the next ones instead of handed back to the system.

glibc's malloc serves each block above its mmap threshold (32 MiB at most) with a mapping of its own and unmaps it
when the block is freed, so every large array starts on fresh pages that the kernel maps one fault at a time. A
64-camera take's dense views are 150 MB an array; a copy of them took 0.28 s on fresh pages and 0.02 s on reused
ones (on this 2-core machine), and the calibration makes such copies in every stage. With blocks served from the
heap and the heap kept, the 64 cameras x 50,000 placements take ran 0.3-0.8 s faster as a whole process at the
same peak memory (benchmarks/limits.py).
"""

from __future__ import annotations

import ctypes
import sys

#: glibc's mallopt parameters (malloc.h).
M_TRIM_THRESHOLD = -1
M_MMAP_MAX = -4
#: Free memory at the heap's top beyond this is handed back to the system (bytes).
KEPT_FREE = 1 << 30


def keep_freed_memory() -> bool:
    """Serve large blocks from malloc's heap and keep up to :data:`KEPT_FREE` of it free for reuse, for the rest of the
    process (a command's start). Returns whether the C library took the settings (False: not glibc, e.g. musl or
    another system; nothing changes then)."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt  # the C library the interpreter runs on
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return bool(mallopt(M_MMAP_MAX, 0)) and bool(mallopt(M_TRIM_THRESHOLD, KEPT_FREE))
