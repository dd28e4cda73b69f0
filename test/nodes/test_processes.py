"""The collector as its own process: bags (mcap, sqlite3, ROS 1 converted) played by another process,
/calibrate from a third, kill -9 and restart, signals while starting and running."""

from __future__ import annotations

import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import wait_until
from rigs import compare_with_true_projections

from wand_calib_ros.core.pipeline import calibrate
from wand_calib_ros.io.bags import write_image_bag
from wand_calib_ros.io.observations_csv import read_observations
from wand_calib_ros.io.result_yaml import read_result
from wand_calib_ros.io.rig_yaml import save_rig
from wand_calib_ros.sim.render import RenderOptions, render_recording
from wand_calib_ros.sim.scenarios import paper_fisheye_scenario

pytest.importorskip("rclpy")

from wand_calib_ros.nodes.launch import child_env, free_domain_id, start, stop


def _trigger(domain_id: int, service: str = "/calibrate") -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "wand_calib_ros.nodes.trigger", service, "--timeout", "120"],
        env=child_env(domain_id),
        capture_output=True,
        text=True,
        timeout=180,
        check=False,
    )


def _frames_in(path: Path) -> int:
    if not path.exists():
        return 0
    lines = path.read_text().splitlines()[1:]
    return len({line.split(",")[0] for line in lines})


@pytest.fixture(scope="module")
def rendered(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, np.ndarray]:
    scenario = paper_fisheye_scenario()
    recording = render_recording(scenario, 300, 30.0, RenderOptions(), np.random.default_rng(21))
    folder = tmp_path_factory.mktemp("rendered")
    for storage in ("mcap", "sqlite3"):
        write_image_bag(folder / storage, recording.frames, scenario.rig.camera_names, storage=storage)
    write_image_bag(folder / "in.bag", recording.frames, scenario.rig.camera_names, storage="ros1")
    convert = shutil.which("rosbags-convert", path=str(Path(sys.executable).parent))
    assert convert is not None
    subprocess.run([convert, "--src", str(folder / "in.bag"), "--dst", str(folder / "ros1")], check=True, timeout=120)
    save_rig(scenario.rig, folder / "cameras.yaml")
    return folder, recording.drawn


@pytest.mark.parametrize("storage", ["mcap", "sqlite3", "ros1"])
def test_collector_process_calibrates_what_another_process_plays(
    rendered: tuple[Path, np.ndarray], tmp_path: Path, storage: str
) -> None:
    folder, drawn = rendered
    scenario = paper_fisheye_scenario()
    domain_id = free_domain_id()
    params = {
        "cameras_file": str(folder / "cameras.yaml"),
        "output_dir": str(tmp_path / "out"),
        "image_qos": "reliable",
        "min_theta_fraction": 0.5,
        "write_report": False,
    }
    collector = start("wand_calib_ros.nodes.collector", params, domain_id=domain_id, log=tmp_path / "collector.log")
    try:
        replay = {"bag": str(folder / storage), "cameras_file": params["cameras_file"], "rate": 3.0}
        player = start("wand_calib_ros.nodes.replay", replay, domain_id=domain_id, log=tmp_path / "replay.log")
        assert player.wait(timeout=120) == 0
        answer = _trigger(domain_id)
        assert answer.returncode == 0, answer.stdout + answer.stderr
        assert "/calibrate: success" in answer.stdout
    finally:
        code = stop(collector, signal.SIGTERM)
    log = (tmp_path / "collector.log").read_text()
    assert code == 0, log
    assert "Traceback" not in log
    observations = read_observations(tmp_path / "out" / "observations.csv", scenario.rig.camera_names)
    assert len(observations.frames) > 250  # of 300, some without the wand or held still
    result = calibrate(scenario.rig, observations)
    _, written = read_result(tmp_path / "out" / "result.yaml")
    assert np.allclose(written["cam0"].model.intrinsic_vector(), result.camera("cam0").model.intrinsic_vector())
    assert compare_with_true_projections(scenario, drawn, observations, result, factor=1.5) == []


def test_kill_9_mid_replay_then_restart_loses_nothing(rendered: tuple[Path, np.ndarray], tmp_path: Path) -> None:
    folder, _ = rendered
    domain_id = free_domain_id()
    buffer = tmp_path / "out" / "observations.csv"
    params = {
        "cameras_file": str(folder / "cameras.yaml"),
        "output_dir": str(tmp_path / "out"),
        "image_qos": "reliable",
        "min_theta_fraction": 0.5,
        "min_placements": 50,
        "min_image_fraction": 0.3,
        "write_report": False,
    }
    first = start("wand_calib_ros.nodes.collector", params, domain_id=domain_id, log=tmp_path / "first.log")
    replay = {"bag": str(folder / "mcap"), "cameras_file": params["cameras_file"], "rate": 1.0}
    player = start("wand_calib_ros.nodes.replay", replay, domain_id=domain_id, log=tmp_path / "replay.log")
    second = None
    try:
        assert wait_until(lambda: _frames_in(buffer) >= 60, 60)
        first.send_signal(signal.SIGKILL)
        first.wait(timeout=10)
        before = buffer.read_text()
        kept = _frames_in(buffer)
        torn = f"{int(before.splitlines()[-1].split(',')[0]) + 1},cam1,C,348.375807,19"
        with buffer.open("a") as handle:  # as if the kill had come in the middle of writing the next frame
            handle.write(torn)
        second = start("wand_calib_ros.nodes.collector", params, domain_id=domain_id, log=tmp_path / "second.log")
        assert player.wait(timeout=120) == 0
        time.sleep(1.0)
        answer = _trigger(domain_id)
        assert answer.returncode == 0, answer.stdout + answer.stderr
    finally:
        stop(player)
        code = stop(second) if second is not None else None
        stop(first)
        cleaner = Path(sys.executable).parent / "fastdds"
        if cleaner.exists():  # the killed process left its shared-memory segments behind
            subprocess.run([str(cleaner), "shm", "clean"], capture_output=True, timeout=60, check=False)
    assert code == 0
    after = buffer.read_text()
    assert after.startswith(before)  # every row written before the kill is still there, in order
    log = (tmp_path / "second.log").read_text()
    assert f"({kept} frames resumed)" in log and "the last write was torn" in log
    assert [p.read_text() for p in buffer.parent.glob("observations.*.torn.csv")] == [before + torn]  # kept aside
    assert torn not in after  # the torn row and its truncated values are gone
    assert _frames_in(buffer) > kept + 30  # and the restarted collector went on adding


@pytest.mark.parametrize(
    ("sig", "moment"),
    [(signal.SIGTERM, "collecting"), (signal.SIGINT, "collecting"), (signal.SIGTERM, "/calibrate reads")],
)
def test_a_signal_while_starting_or_running_stops_the_collector_cleanly(tmp_path: Path, sig: int, moment: str) -> None:
    # "collecting" is logged while the calibrator node is still being built (ROS is up by then;
    # a signal during the interpreter's own start-up, before any ROS, ends it the default way).
    save_rig(paper_fisheye_scenario().rig, tmp_path / "cameras.yaml")
    params = {"cameras_file": str(tmp_path / "cameras.yaml"), "output_dir": str(tmp_path / "out")}
    log = tmp_path / "log"
    collector = start("wand_calib_ros.nodes.collector", params, domain_id=free_domain_id(), log=log)
    assert wait_until(lambda: moment in log.read_text(), 60, step_s=0.005)
    assert stop(collector, sig, timeout_s=30) == 0
    assert "Traceback" not in log.read_text()


def test_stopping_the_calibrator_during_a_calibration_answers_the_caller(tmp_path: Path) -> None:
    from wand_calib_ros.io.observations_csv import write_observations
    from wand_calib_ros.sim.scenarios import mocap_scenario, simulate

    scenario = mocap_scenario()  # 6,000 placements of 16 cameras: a solve of several seconds
    save_rig(scenario.rig, tmp_path / "cameras.yaml")
    (tmp_path / "out").mkdir()
    observations = simulate(scenario, 1.0, np.random.default_rng(0), n=6000).observations
    write_observations(observations, tmp_path / "out" / "observations.csv")
    domain_id = free_domain_id()
    params = {
        "cameras_file": str(tmp_path / "cameras.yaml"),
        "output_dir": str(tmp_path / "out"),
        "require_coverage": False,
        "write_report": False,
    }
    log = tmp_path / "calibrator.log"
    calibrator = start("wand_calib_ros.nodes.calibrator", params, domain_id=domain_id, log=log)
    caller = subprocess.Popen(
        [sys.executable, "-m", "wand_calib_ros.nodes.trigger", "/calibrate", "--timeout", "120"],
        env=child_env(domain_id),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        assert wait_until(lambda: "calibrating 6000 frames" in log.read_text(), 60)
        assert stop(calibrator, signal.SIGINT) == 0
        answer, _ = caller.communicate(timeout=60)
    finally:
        stop(caller)
        stop(calibrator)
    assert "/calibrate: failure: the calibrator was stopped" in answer  # answered, not left hanging
    assert "Traceback" not in log.read_text() and "InvalidHandle" not in log.read_text()
