"""How long ``ros2 service call /calibrate std_srvs/srv/Trigger`` takes on a live take, as a user meets it.

Renders the paper's three-camera rig (640x480 fisheyes) while a wand is waved for ``--seconds`` (30 s),
publishes the images in real time (30 fps, sensor-data QoS as a driver does, on the large-image Fast DDS
profile the package ships: on the default one these drivers lose a quarter of them) into a ``collector``
process started with nothing but ``cameras_file`` and ``output_dir`` (its defaults otherwise: the report
on, the running estimate on), waits until it has stored them, then times whole ``ros2 service call``
processes:

- the calibrator node's own ``get_parameters`` (rcl_interfaces/srv/GetParameters): the CLI's own start,
  its node's discovery of the service and one call answered at once;
- then ``/calibrate`` (std_srvs/srv/Trigger).

The difference from the first's median is the time the answer takes beyond the CLI's own start (target
1.0 s). It also prints when the collector's log said the report was ready, and how long it took.

With the ``ros2`` command line (ros2cli: not on PyPI; for checking by hand it installs from its public
sources, ``../shared/ros2-wheels.md``, "A real ros2 CLI"; or give ``--ros2`` a path). Without it, the
package's own ``trigger`` as a process, against ``/refine`` for its own start (before any calibration,
``/refine`` answers at once); the output says which.

Run: .venv/bin/python benchmarks/live_calibrate.py [--seconds 30] [--calls 3]
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Image

from wand_calib_ros.io.rig_yaml import save_rig
from wand_calib_ros.nodes.launch import free_domain_id, start, stop
from wand_calib_ros.nodes.messages import array_to_image
from wand_calib_ros.nodes.runner import use_large_image_transport
from wand_calib_ros.sim.render import RenderOptions, render_recording
from wand_calib_ros.sim.scenarios import paper_three_camera_scenario

FPS = 30.0
#: A log line of rclpy: ``[INFO] [1765000000.123456789] [node]: text``.
LOG_LINE = re.compile(r"\[(\w+)\] \[(\d+\.\d+)\] \[[^\]]+\]: (.*)")


def _callers(explicit: Path | None) -> tuple[list[str], list[str], str]:
    """The commands that call /calibrate and that measure the caller's own start, and what succeeded says."""
    ros2 = explicit or (Path(sys.executable).parent / "ros2")
    if not ros2.is_file():
        ros2 = Path(shutil.which("ros2") or "")
    if ros2.is_file():
        print(f"calling with {ros2} service call")
        own = [str(ros2), "service", "call", "/wand_calib_calibrator/get_parameters",
               "rcl_interfaces/srv/GetParameters", "{names: [write_report]}"]  # fmt: skip
        return [str(ros2), "service", "call", "/calibrate", "std_srvs/srv/Trigger"], own, "success=True"
    if explicit is not None:
        sys.exit(f"--ros2 {explicit}: no such file")
    print("no ros2 command line: calling with python -m wand_calib_ros.nodes.trigger (see the docstring)")
    trigger = [sys.executable, "-m", "wand_calib_ros.nodes.trigger"]
    return [*trigger, "/calibrate"], [*trigger, "/refine"], ": success: "


def _timed(command: list[str], env: dict[str, str]) -> tuple[float, str]:
    """Seconds a whole process took, and its output."""
    began = time.perf_counter()
    done = subprocess.run(command, env=env, capture_output=True, text=True, timeout=300)
    return time.perf_counter() - began, done.stdout + done.stderr


def _log_lines(path: Path) -> list[tuple[float, str]]:
    """The log's lines as (wall-clock time, text)."""
    return [(float(m[2]), m[3]) for m in map(LOG_LINE.search, path.read_text(errors="replace").splitlines()) if m]


def _cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _publish(domain_id: int, names: tuple[str, ...], frames: list[dict[str, Image]], collector: int) -> None:
    """Publish ``frames`` at 30 fps, then wait until the collector's received counts stop growing."""
    context = Context()
    rclpy.init(context=context, domain_id=domain_id)
    node = Node("benchmark_camera_drivers", context=context)
    publishers = {name: node.create_publisher(Image, f"/{name}/image_raw", qos_profile_sensor_data) for name in names}
    received: dict[str, int] = {}
    totals: list[int] = []  # the received total of each diagnostics message

    def on_diagnostics(array: DiagnosticArray) -> None:
        for status in array.status:
            values = {v.key: v.value for v in status.values}
            if "received" in values:
                received[status.hardware_id] = int(values["received"])
        totals.append(sum(received.values()))

    node.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, 10)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and not all(p.get_subscription_count() for p in publishers.values()):
            time.sleep(0.05)
        time.sleep(1.0)
        begin, cpu = time.monotonic(), _cpu_seconds(collector)
        for k, frame in enumerate(frames):
            delay = begin + k / FPS - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            for name, message in frame.items():
                publishers[name].publish(message)
        published, seconds = sum(len(frame) for frame in frames), time.monotonic() - begin
        cpu = _cpu_seconds(collector) - cpu
        while len(totals) < 3 or len(set(totals[-3:])) > 1:  # until three diagnostics in a row agree
            time.sleep(0.5)
        print(
            f"  published {published} images in {seconds:.1f} s; the collector took {totals[-1]} "
            f"(CPU {100 * cpu / seconds:.0f} % of one core while they came)"
        )
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)
        spinner.join(timeout=5)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=30.0, help="length of the take (s)")
    parser.add_argument("--calls", type=int, default=3, help="calls of each kind")
    parser.add_argument("--ros2", type=Path, help="the ros2 command (default: the venv's, then PATH)")
    parser.add_argument("--keep", type=Path, help="keep the collector's output here (default: a temporary folder)")
    args = parser.parse_args()
    calibrate, own, succeeded = _callers(args.ros2)
    shell = dict(os.environ)  # what the caller runs with: a user's shell, without the drivers' profile
    use_large_image_transport(os.environ)  # (the drivers'; before this process's first participant)
    scenario = paper_three_camera_scenario()
    names = scenario.rig.camera_names
    n_frames = int(args.seconds * FPS)
    print(f"rendering {n_frames} frames x {len(names)} cameras at {scenario.rig.cameras[0].image_size} ...")
    options = RenderOptions(centre_scatter_px=0.3, reflection_rate=0.02)  # centres as a real camera finds them
    recording = render_recording(scenario, n_frames, FPS, options, np.random.default_rng(0))
    index = {stamp: k for k, stamp in enumerate(sorted({int(stamp) for _, stamp, _ in recording.frames}))}
    frames: list[dict[str, Image]] = [{} for _ in index]
    for camera, stamp, pixels in recording.frames:
        frames[index[int(stamp)]][camera] = array_to_image(pixels, stamp, camera)
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.keep or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        save_rig(scenario.rig, folder / "cameras.yaml")
        domain_id = free_domain_id()
        log = folder / "collector.log"
        params = {"cameras_file": str(folder / "cameras.yaml"), "output_dir": str(folder / "out")}
        collector = start("wand_calib_ros.nodes.collector", params, domain_id=domain_id, log=log)
        env = {**shell, "ROS_DOMAIN_ID": str(domain_id), "AMENT_PREFIX_PATH": str(Path(sys.executable).parent.parent)}
        env.pop("_ROS_WHEELS_BOOTSTRAP_COMPLETE", None)  # the CLI's interpreter sets its library path again
        try:
            _publish(domain_id, names, frames, collector.pid)
            # (first, while /refine answers at once; the first call of all, whose discovery can take seconds
            # more, is not counted)
            starts = [_timed(own, env)[0] for _ in range(args.calls + 1)]
            print(f"  the caller's own start: {' '.join(f'{s:.2f}' for s in starts)} s (the first not counted)")
            starts = starts[1:]
            answers, inside = [], []
            for _ in range(args.calls):
                called_at = time.time()
                seconds, text = _timed(calibrate, env)
                answers.append(seconds)
                success = succeeded in text
                print(f"  /calibrate: {seconds:.2f} s, success {success}")
                if not success:
                    print("   ", text.strip().splitlines()[-1][:300])
                time.sleep(4.0)  # the report, drawn after the answer
                lines = [(at, line) for at, line in _log_lines(log) if at > called_at]
                began = next(at for at, line in lines if line.startswith("calibrating "))
                said = [at for at, line in lines if line.startswith("/calibrate: ") and "report ready" not in line]
                answered = said[0]
                inside.append(answered - began)
                for at, line in lines:
                    if "report" in line:
                        print(f"    log {at - answered:+.2f} s from the answer: {line[:150]}")
            own_start = float(np.median(starts))
            beyond = np.array(answers) - own_start
            print(
                f"/calibrate answered {beyond.min():.2f}-{beyond.max():.2f} s beyond the caller's own start (median "
                f"{own_start:.2f} s, {min(starts):.2f}-{max(starts):.2f} s with its discovery); whole call "
                f"{min(answers):.2f}-{max(answers):.2f} s (target: 1.0 s beyond). In the calibrator, from its "
                f"'calibrating' line to its answer: {min(inside):.2f}-{max(inside):.2f} s"
            )
        finally:
            print(f"collector exit code {stop(collector)}")


if __name__ == "__main__":
    main()
