"""What importing the package sets for the process (``wand_calib_ros/__init__.py``)."""

from __future__ import annotations

import subprocess
import sys

import pytest

#: A bundle adjustment's pattern: several arrays of a few MB allocated, used and freed, over and over;
#: prints the page faults per round once warm.
ROUNDS = """
import resource, sys
if sys.argv[1] == "package":
    import wand_calib_ros
import numpy as np

def work():
    if sys.argv[2] == "large":
        arrays = [np.ones(8_000_000 + 10_000 * i) for i in range(2)]  # 64 MB each
    else:
        arrays = [np.ones(200_000 + 10_000 * i) for i in range(8)]  # 1.6 to 2.2 MB each
    return sum(float(a[0]) for a in arrays)

work(), work()
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(20):
    work()
print((resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before) / 20)
"""


def _faults_per_round(which: str, env: dict[str, str] | None = None, arrays: str = "small") -> float:
    done = subprocess.run(
        [sys.executable, "-c", ROUNDS, which, arrays], capture_output=True, text=True, check=True, env=env, timeout=60
    )
    return float(done.stdout)


def test_openblas_runs_one_thread_unless_the_user_says_otherwise() -> None:
    code = "import os, wand_calib_ros; print(os.environ['OPENBLAS_NUM_THREADS'])"
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True).stdout.strip() == "1"
    env = {"OPENBLAS_NUM_THREADS": "2", "PATH": ""}
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env).stdout.strip() == "2"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's allocator")
def test_freed_memory_is_kept_so_arrays_of_a_few_mb_do_not_fault_their_pages_in_again() -> None:
    # 8 arrays of 2 MB: 4,000 pages; glibc by default gives them back and faults them in every round
    assert _faults_per_round("numpy only") > 1000
    assert _faults_per_round("package") < 10
    # a user's own allocator setting is left alone (any of glibc's tunables turns its dynamic thresholds off)
    assert _faults_per_round("package", {"MALLOC_TRIM_THRESHOLD_": "131072", "PATH": ""}) > 1000


def test_numpy_asks_for_no_huge_pages_unless_the_user_says_otherwise() -> None:
    code = "import wand_calib_ros, numpy; print(numpy._core.multiarray._get_madvise_hugepage())"

    def advised(env: dict[str, str] | None) -> str:
        return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env).stdout.strip()

    assert advised(None) == "False"
    assert advised({"NUMPY_MADVISE_HUGEPAGE": "1", "PATH": ""}) == "True"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's allocator")
def test_large_arrays_reuse_freed_memory_too() -> None:
    # 2 arrays of 64 MB, above any mmap threshold glibc allows: mapped and unmapped one by one where a user's
    # setting allows mappings (32,000 pages faulted in a round); from the heap, the freed memory serves the next
    assert _faults_per_round("package", arrays="large") < 100
    assert _faults_per_round("package", {"MALLOC_MMAP_MAX_": "65536", "PATH": ""}, arrays="large") > 10_000
