"""Two halves of a computation on two cores.

numpy releases the interpreter lock inside its loops, so two threads working through separate
halves of a large vectorised computation (chunks of observations, cameras' rays) run side by side
for most of their time. The halves must write disjoint parts of their outputs (or their own
accumulators, joined afterwards).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor


def cores() -> int:
    """The processor cores this process may run on."""
    affinity = getattr(os, "sched_getaffinity", None)
    return len(affinity(0)) if affinity is not None else os.cpu_count() or 1


def both(first: Callable[[], None], second: Callable[[], None], *, split: bool = True) -> None:
    """Run ``first`` and ``second``: side by side (``second`` in a worker thread) when ``split`` and the process
    may use two cores, else one after the other. An exception of either is raised here."""
    if not split or cores() < 2:
        first()
        second()
        return
    with ThreadPoolExecutor(max_workers=1) as pool:
        done = pool.submit(second)
        first()
        done.result()
