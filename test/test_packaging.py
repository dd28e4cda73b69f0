"""The package installs with plain pip (console script on PATH) and carries its ament resources."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SOURCES = ("setup.py", "setup.cfg", "package.xml", "pyproject.toml", "README.md", "LICENSE", "resource", "config")


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
    assert (prefix / "share" / "ament_index" / "resource_index" / "packages" / "wand_calib_ros").exists()
    assert (prefix / "share" / "wand_calib_ros" / "package.xml").exists()
    assert (prefix / "share" / "wand_calib_ros" / "config" / "paper_fisheye_pair.yaml").exists()
    site = next(prefix.glob("lib/python3*/site-packages"))
    env = {**os.environ, "PYTHONPATH": str(site)}
    completed = subprocess.run(
        [sys.executable, str(script), "--help"], capture_output=True, text=True, env=env, timeout=120
    )
    assert completed.returncode == 0 and "calibrate" in completed.stdout
