"""wand_calib_ros: multi-camera wand calibration (Fu, Quan & Cai) for ROS 2.

Layers, lowest first; each imports only those before it (``test/test_layout.py``): ``errors``,
``core`` (the method: model, adjust, judge, initialise, after), ``io`` (files), ``report``,
``collection`` (live buffering, sync, coverage, the running estimate), ``detection`` (images to wand
points), ``sim`` (synthetic rigs), ``commands`` (one module per subcommand), ``cli`` (the ``wand-calib``
command built from them) and ``nodes`` (ROS 2, the only layer importing rclpy).

Importing the package tunes three process-wide settings for a calibration's workload, each left alone
when the user set it:

- OpenBLAS uses one thread (unless ``OPENBLAS_NUM_THREADS`` is set, which only works before numpy
  is imported): a calibration is many small matrix products, where numpy's and scipy's two OpenBLAS
  thread pools contend for the cores and cost more than they give (``benchmarks/stages.py``: 4.8 s
  against 5.9 s in-process on 16 cameras x 10,000 placements, on two cores).
- glibc's allocator keeps freed memory (unless a ``MALLOC_*_`` tunable is set, see
  :func:`_keep_freed_memory`).
- numpy does not ask the kernel for huge pages under its large arrays (unless ``NUMPY_MADVISE_HUGEPAGE`` is
  set, which too only works before numpy is imported). Where the kernel compacts memory to find a huge page on
  a fault (transparent huge pages with ``defrag`` at ``madvise``, the usual setting), a fresh array can stall:
  here a 150 MB copy took 0.3 s with the advice and 0.06 s without, and ``wand-calib calibrate`` ran faster
  without it, interleaved runs: 64 cameras x 50,000 placements 12.20 against 12.68 s (median of 3), mocap16's
  452k rows 3.01 against 3.14 s (median of 5).
"""

import ctypes
import os
import sys

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("NUMPY_MADVISE_HUGEPAGE", "0")

__version__ = "0.1.0"

#: glibc's mallopt parameters (malloc.h) and the values set.
_M_TRIM_THRESHOLD, _M_MMAP_MAX = -1, -4
TRIM_THRESHOLD_BYTES = 1 << 30
#: Blocks glibc may serve with mappings of their own at once: none, every block comes from the heap.
MMAP_MAX = 0


def _keep_freed_memory() -> bool:
    """Have glibc serve every block from its heap and keep up to TRIM_THRESHOLD_BYTES of it free; True when set.

    A bundle adjustment allocates and frees arrays of a few MB per iteration. By default glibc gives
    the top of the heap back to the system whenever a few MB of it are free (its trim threshold
    follows twice the largest block freed so far), and the next iteration's arrays fault the same
    pages in again, zeroed by the kernel: on the live benchmark's buffer (570 frames, 4 cameras)
    29,600 page faults per calibration and a fifth of its time; with these settings 20 faults (4,300
    on the first), the calibration's peak memory unchanged. Blocks above glibc's mmap threshold (32 MB
    at most) it maps and unmaps one by one, so each of a large rig's arrays (150 MB of dense views, the
    normal equations' W of 240 MB at 64 cameras) started on fresh pages. From the heap, and with up to
    a GiB of it kept, 64 cameras x 50,000 placements fault each page of their 0.98 GB peak in once
    (250,000 faults, 400,000 with 64 MB kept): interleaved runs 10.86 s against 11.83 s with 64 MB kept
    and 12.36 s with mappings (medians of 3, faster in every pair), at the same peak memory; mocap16's
    452k rows (arrays under 32 MB) 2.94 against 2.95 s. The memory kept is what the process's largest
    stage needed: its peak, not more. Linux with glibc only; a no-op elsewhere.
    """
    if not sys.platform.startswith("linux"):
        return False
    tunables = ("MALLOC_TRIM_THRESHOLD_", "MALLOC_MMAP_THRESHOLD_", "MALLOC_MMAP_MAX_", "MALLOC_TOP_PAD_")
    if any(name in os.environ for name in tunables):
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt  # the process's C library (numpy loads ctypes anyway)
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return bool(mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES) and mallopt(_M_MMAP_MAX, MMAP_MAX))


_keep_freed_memory()
