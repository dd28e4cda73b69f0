"""Node start-up under bad settings: exit code 2 and one FATAL line naming the file or parameter, as processes.

(The parameter types and ranges themselves are in test_params.py, in one process.)
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from wand_calib_ros.io.rig_yaml import save_rig
from wand_calib_ros.nodes.launch import child_env, free_domain_id, ros_args, start, stop
from wand_calib_ros.sim.scenarios import paper_fisheye_scenario

pytest.importorskip("rclpy")


def _run(module: str, *args: str, timeout_s: float = 60.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", module, *args],
        env=child_env(free_domain_id()),
        capture_output=True,
        text=True,
        timeout=timeout_s,
        check=False,
    )


@pytest.fixture
def rig_file(tmp_path: Path) -> Path:
    save_rig(paper_fisheye_scenario().rig, tmp_path / "cameras.yaml")
    return tmp_path / "cameras.yaml"


def _fatal_lines(output: str) -> list[str]:
    return [line for line in output.splitlines() if "[FATAL]" in line or "[ERROR]" in line]


@pytest.mark.parametrize(
    ("content", "expected"),
    [
        (None, "cannot read: No such file or directory"),
        ("a: [b\n", "not valid YAML"),
        (b"\x89PNG\r\n\x1a\n\xff\xfe", "not valid YAML"),
    ],
    ids=["missing", "malformed", "binary"],
)
def test_a_params_file_that_cannot_be_read_is_named(tmp_path: Path, content: str | bytes | None, expected: str) -> None:
    path = tmp_path / "params.yaml"
    if isinstance(content, bytes):
        path.write_bytes(content)
    elif content is not None:
        path.write_text(content)
    done = _run("wand_calib_ros.nodes.collector", "--ros-args", "--params-file", str(path))
    lines = _fatal_lines(done.stdout + done.stderr)
    assert done.returncode == 2, done.stderr
    assert len(lines) == 1 and f"parameter file {path}: {expected}" in lines[0], done.stderr
    assert "Traceback" not in done.stderr


def test_a_misspelt_parameter_is_warned_about_with_the_name_it_resembles(tmp_path: Path, rig_file: Path) -> None:
    params = tmp_path / "params.yaml"
    params.write_text(f"/**:\n  ros__parameters:\n    cameras_file: {rig_file}\n    sync_tolerance: 5.0\n")
    log = tmp_path / "log"
    collector = start(
        "wand_calib_ros.nodes.collector",
        {"output_dir": str(tmp_path / "out"), "min_placemnts": 3},
        domain_id=free_domain_id(),
        log=log,
        arguments=["--ros-args", "--params-file", str(params)],
    )
    deadline = time.monotonic() + 60
    while "did you mean" not in log.read_text() and time.monotonic() < deadline and collector.poll() is None:
        time.sleep(0.1)
    assert stop(collector) == 0
    text = log.read_text()
    assert "parameter sync_tolerance is not a parameter of" in text and "(did you mean sync_tolerance_ms?)" in text
    assert "parameter min_placemnts is not a parameter of" in text and "(did you mean min_placements?)" in text


def test_an_output_dir_that_is_a_file_is_named(tmp_path: Path, rig_file: Path) -> None:
    (tmp_path / "plain").write_text("a file\n")
    done = _run(
        "wand_calib_ros.nodes.collector",
        *ros_args({"cameras_file": str(rig_file), "output_dir": str(tmp_path / "plain" / "out")}),
    )
    lines = _fatal_lines(done.stdout + done.stderr)
    assert done.returncode == 2 and len(lines) == 1, done.stderr
    assert f"{tmp_path / 'plain'} is a file, not a folder" in lines[0]


def test_replaying_a_corrupt_bag_exits_2(tmp_path: Path, rig_file: Path) -> None:
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "metadata.yaml").write_text("not: a bag\n")
    done = _run(
        "wand_calib_ros.nodes.replay",
        *ros_args({"bag": str(bag), "cameras_file": str(rig_file), "wait_for_subscribers_s": 0.0}),
    )
    lines = _fatal_lines(done.stdout + done.stderr)
    assert done.returncode == 2 and len(lines) == 1 and f"cannot play {bag}" in lines[0], done.stderr


@pytest.mark.parametrize("delay_s", [0.15, 0.5])
def test_sigterm_in_the_first_second_exits_0(tmp_path: Path, rig_file: Path, delay_s: float) -> None:
    log = tmp_path / "log"
    params = {"cameras_file": str(rig_file), "output_dir": str(tmp_path / "out")}
    collector = start("wand_calib_ros.nodes.collector", params, domain_id=free_domain_id(), log=log)
    time.sleep(delay_s)  # still importing rclpy
    assert stop(collector, signal.SIGTERM) == 0
    assert "Traceback" not in log.read_text()
