"""The live nodes' files as Unix tools write them: through symbolic links, with the umask's permissions."""

from __future__ import annotations

import os
import stat
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import Ros, points_rig

from wand_calib_ros.io.observations_csv import read_observations
from wand_calib_ros.io.result_yaml import read_result
from wand_calib_ros.sim.scenarios import paper_fisheye_scenario, simulate

rclpy = pytest.importorskip("rclpy")

from std_srvs.srv import Trigger  # noqa: E402


def _mode(path: Path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


def test_collector_and_calibrator_write_through_links_with_the_umask(ros: Ros, tmp_path: Path) -> None:
    scenario = paper_fisheye_scenario()
    data = simulate(scenario, 0.5, np.random.default_rng(4), n=400)
    out, elsewhere = tmp_path / "out", tmp_path / "elsewhere"
    out.mkdir()
    elsewhere.mkdir()
    # the buffer through a link to a file not made yet; the result through a link to a file kept 0640
    (out / "observations.csv").symlink_to(elsewhere / "buffer.csv")
    (elsewhere / "result.yaml").write_text("an older result\n")
    (elsewhere / "result.yaml").chmod(0o640)
    (out / "result.yaml").symlink_to(elsewhere / "result.yaml")
    before = os.umask(0o022)
    try:
        rig = points_rig(ros, scenario, tmp_path, {"min_theta_fraction": 0.5})
        rig.play(data.observations.uv)
        calibrate = ros.helper.create_client(Trigger, "calibrate")
        assert calibrate.wait_for_service(timeout_sec=5)
        answer = calibrate.call(Trigger.Request(), timeout_sec=120)
        assert answer.success, answer.message
    finally:
        os.umask(before)

    # the links stay; their targets hold what was written
    assert (out / "observations.csv").is_symlink() and (out / "result.yaml").is_symlink()
    kept = read_observations(elsewhere / "buffer.csv")
    assert len(kept.frames) == len(rig.collector.session.buffer.frames) > 300
    assert set(read_result(elsewhere / "result.yaml")[1]) == {"cam0", "cam1"}
    assert _mode(elsewhere / "result.yaml") == 0o640  # an existing file keeps its permissions
    # new files take the umask's: the buffer, the lock, camera_info (was 0600 through mkstemp)
    news = [elsewhere / "buffer.csv", *sorted((out / "camera_info").glob("*.yaml"))]
    assert len(news) == 1 + len(scenario.cameras)
    assert {path.name: _mode(path) for path in news} == dict.fromkeys((p.name for p in news), 0o644)

    # nothing staged is left behind (the collector's own lock file only); a write in flight, such as the
    # collector's periodic observations.detection.yaml, is renamed into place once its thread runs again: within
    # milliseconds, or after the report drawn beside it releases the interpreter (1-3 s on two busy cores: a CI
    # run saw one still staged after 2 s)
    def staged() -> list[str]:
        return [p.name for p in [*out.rglob("*"), *elsewhere.rglob("*")] if p.name.startswith(".") or "tmp" in p.name]

    lock = [p.name for p in out.glob(".*lock*")]
    deadline = time.monotonic() + 10.0
    while staged() != lock and time.monotonic() < deadline:
        time.sleep(0.05)
    assert staged() == lock

    # /reset keeps the link: the take goes to a backup beside it, the target starts again empty
    reset = ros.helper.create_client(Trigger, "reset")
    assert reset.wait_for_service(timeout_sec=5)
    assert reset.call(Trigger.Request(), timeout_sec=10).success
    assert (out / "observations.csv").is_symlink()
    assert (out / "observations.csv").resolve() == elsewhere / "buffer.csv"
    backups = list(out.glob("observations.*.bak.csv"))
    assert len(backups) == 1 and not backups[0].is_symlink() and _mode(backups[0]) == 0o644
    assert len(read_observations(backups[0]).frames) == len(kept.frames)
    assert (elsewhere / "buffer.csv").read_text().startswith("frame,camera,point,u,v")
    assert (elsewhere / "buffer.csv").read_text().count("\n") == 1  # the header alone
    rig.play(data.observations.uv[:60])  # the next take goes on into the link's target
    assert len(read_observations(elsewhere / "buffer.csv").frames) > 40
