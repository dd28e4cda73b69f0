"""The bump watch keeps at most MAX_PENDING frames waiting for its worker (a slow rig stays current)."""

from __future__ import annotations

import numpy as np
from rigs import scenario_data

from wand_calib_ros.collection.watch import MAX_PENDING, BumpWatch
from wand_calib_ros.core.pipeline import calibrate


def test_frames_waiting_for_the_worker_are_bounded_and_judged() -> None:
    scenario, data, held = scenario_data("paper3", 0, noise=1.0)
    watch = BumpWatch(scenario.rig, calibrate(scenario.rig, data.observations))
    try:
        for frame in np.concatenate([held.observations.uv] * 5):  # 500 frames offered, none judged yet
            watch.offer(frame)
        assert len(watch._pending) == MAX_PENDING
        watch.step()
        assert watch._running is not None
        watch._running.result(timeout=30)
        assert watch.moved() == {} and len(watch._pending) == 0
    finally:
        watch.close()
