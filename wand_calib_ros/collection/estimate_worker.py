"""The running estimate's worker process (:mod:`wand_calib_ros.collection.estimate`).

Kept apart and light: a spawned process imports this module first, so it lowers its own CPU priority
before numpy, scipy and the pipeline are loaded; on a busy machine detection goes first.
"""

from __future__ import annotations

import os
from multiprocessing.connection import Connection


def serve(connection: Connection) -> None:
    """One round per request (the arguments of ``calibrate_round``) until the pipe closes or says None."""
    os.nice(19)  # before the imports: loading scipy takes a core for a second
    from wand_calib_ros.collection.estimate_round import calibrate_round

    while True:
        try:
            request = connection.recv()
        except (EOFError, OSError):  # the node went away
            return
        if request is None:
            return
        answer = calibrate_round(*request)
        try:
            connection.send(answer)
        except OSError:  # the node went away while the round ran (BrokenPipeError)
            return
