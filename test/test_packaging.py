"""The package installs with plain pip (console scripts on PATH) and builds with colcon (ros2 run finds it)."""

from __future__ import annotations

import os
import random
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SOURCES = (
    "setup.py",
    "setup.cfg",
    "package.xml",
    "pyproject.toml",
    "README.md",
    "LICENSE",
    "resource",
    "config",
    "launch",
)
NODES = ("collector", "calibrator", "detector", "replay", "trigger")


def test_plain_pip_install_puts_the_console_script_and_ament_resources_in_place(tmp_path: Path) -> None:
    source = tmp_path / "src"
    source.mkdir()
    for name in SOURCES:
        target = source / name
        (shutil.copytree if (ROOT / name).is_dir() else shutil.copy)(ROOT / name, target)
    shutil.copytree(ROOT / "wand_calib_ros", source / "wand_calib_ros", ignore=shutil.ignore_patterns("__pycache__"))
    prefix = tmp_path / "prefix"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "--quiet",
            "--no-deps",
            "--no-build-isolation",
            "--ignore-installed",  # leave the development install of this venv alone
            "--prefix",
            str(prefix),
            str(source),
        ],
        check=True,
        capture_output=True,
        text=True,
        timeout=300,
    )
    script = prefix / "bin" / "wand-calib"
    assert script.exists()
    for node in NODES:  # on a user's PATH with the package's prefix, never as a generic "collector"
        assert (prefix / "bin" / f"wand-calib-{node}").exists(), node
        assert not (prefix / "bin" / node).exists(), node
    assert (prefix / "share" / "ament_index" / "resource_index" / "packages" / "wand_calib_ros").exists()
    assert (prefix / "share" / "wand_calib_ros" / "package.xml").exists()
    assert (prefix / "share" / "wand_calib_ros" / "config" / "paper_fisheye_pair.yaml").exists()
    site = next(prefix.glob("lib/python3*/site-packages"))
    assert (site / "wand_calib_ros" / "nodes" / "fastdds_large_images.xml").exists()
    env = {**os.environ, "PYTHONPATH": str(site)}
    completed = subprocess.run(
        [sys.executable, str(script), "--help"], capture_output=True, text=True, env=env, timeout=120
    )
    assert completed.returncode == 0 and "calibrate" in completed.stdout
    completed = subprocess.run(
        [sys.executable, str(prefix / "bin" / "wand-calib-collector"), "--help"],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    assert completed.returncode == 0 and "parameters of wand_calib_collector" in completed.stdout


def test_colcon_build_then_start_the_collector_as_ros2_run_would(tmp_path: Path) -> None:
    colcon = Path(sys.executable).parent / "colcon"
    assert colcon.exists(), "colcon-common-extensions is a development requirement"
    package = tmp_path / "ws" / "src" / "wand_calib_ros"
    package.mkdir(parents=True)
    for name in SOURCES:
        (shutil.copytree if (ROOT / name).is_dir() else shutil.copy)(ROOT / name, package / name)
    shutil.copytree(ROOT / "wand_calib_ros", package / "wand_calib_ros", ignore=shutil.ignore_patterns("__pycache__"))
    workspace = tmp_path / "ws"
    built = subprocess.run([str(colcon), "build"], cwd=workspace, capture_output=True, text=True, timeout=600)
    assert built.returncode == 0, built.stdout + built.stderr
    # `ros2 run wand_calib_ros collector`: the ament index gives the prefix, the executable is lib/<pkg>/<exe>.
    resolve = (
        "source install/setup.bash && python -c 'from ament_index_python.packages import get_package_prefix, "
        'get_package_share_directory as share; print(get_package_prefix("wand_calib_ros")); '
        'print(share("wand_calib_ros"))\' && env -0'
    )
    env_path = f"{Path(sys.executable).parent}:{os.environ['PATH']}"
    shell = subprocess.run(
        ["bash", "-c", resolve], cwd=workspace, capture_output=True, env={**os.environ, "PATH": env_path}, timeout=120
    )
    assert shell.returncode == 0, shell.stderr.decode()
    prefix, share, environ = shell.stdout.decode().split("\n", 2)
    environment = dict(item.split("=", 1) for item in environ.split("\0") if "=" in item)
    executable = Path(prefix) / "lib" / "wand_calib_ros" / "collector"
    assert executable.exists() and Path(prefix) == workspace / "install" / "wand_calib_ros"
    for node in NODES:
        assert (Path(prefix) / "lib" / "wand_calib_ros" / node).exists(), node
    assert (Path(share) / "launch" / "wand_calib.launch.py").exists()
    params = Path(share) / "config" / "collector.params.yaml"
    assert (Path(share) / "config" / "paper_fisheye_pair.yaml").exists() and params.exists()
    environment["ROS_DOMAIN_ID"] = str(random.SystemRandom().randrange(30, 200))
    log = tmp_path / "collector.log"
    elsewhere = tmp_path / "elsewhere"  # not the source tree: the params file's config/... comes from share/
    elsewhere.mkdir()
    command = [str(executable), "--ros-args", "--params-file", str(params), "-r", "__node:=my_collector"]
    with log.open("wb") as output:
        process = subprocess.Popen(
            [*command, "-p", f"output_dir:={tmp_path / 'out'}"],
            cwd=elsewhere,
            env=environment,
            stdout=output,
            stderr=subprocess.STDOUT,
        )
    try:
        deadline = time.monotonic() + 60
        while "/calibrate reads" not in log.read_text() and time.monotonic() < deadline:
            assert process.poll() is None, log.read_text()
            time.sleep(0.2)
        text = log.read_text()
        assert "collecting cam0, cam1" in text and "/calibrate reads" in text
        # The rename is the collector's; the calibrator keeps its name (and its params-file section).
        assert "[my_collector]: collecting" in text and "[wand_calib_calibrator]: /calibrate reads" in text
        assert "is not a parameter" not in text, text
    finally:
        process.send_signal(signal.SIGTERM)
        code = process.wait(timeout=30)
    assert code == 0, log.read_text()
    assert (tmp_path / "out" / "observations.csv").read_text().startswith("frame,camera,point,u,v")
