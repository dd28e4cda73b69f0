"""Sustained image rate of the live collector, and /calibrate latency.

Publishes 4 cameras x 1280x1024 mono8 x 30 fps (a rendered waved wand, looped)
from this process into a ``collector`` process for ``--seconds``, reads the
collector's per camera "received" counts from /diagnostics, and reports dropped
frames and the collector's CPU use and memory (resident at the end of the publishing, and its peak);
then times ``/calibrate`` on what it stored: the answer to a client
that had found the service before (the service's own latency), then a fresh ``trigger /calibrate``
(its node's discovery of the service included, 0.1-2 s with Fast DDS here).
Runs with the image QoS the collector uses by default (sensor data, best effort)
and with reliable delivery, once with the publishing "drivers" on Fast DDS's
default transport and once with the package's large-image profile
(``wand_calib_ros/nodes/fastdds_large_images.xml``), each in its own process. The collector runs with
its defaults otherwise, the running estimate included (rounds every 3 s in its worker process).

Run: .venv/bin/python benchmarks/live_collector.py [--seconds 20]
Target on this 2-core machine: no dropped frames at 4 x 1280x1024 x 30 fps.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
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
from rclpy.qos import QoSProfile, qos_profile_sensor_data
from sensor_msgs.msg import Image
from std_srvs.srv import Trigger

from wand_calib_ros.io.rig_yaml import save_rig
from wand_calib_ros.nodes.launch import free_domain_id, start, stop
from wand_calib_ros.nodes.messages import array_to_image
from wand_calib_ros.nodes.runner import use_large_image_transport
from wand_calib_ros.nodes.trigger import call_trigger
from wand_calib_ros.sim.render import RenderOptions, render_recording
from wand_calib_ros.sim.scenarios import mocap_scenario

FPS = 30.0


def _cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _memory_mb(pid: int) -> tuple[float, float]:
    """A process's resident memory now and at its peak, MB."""
    fields = dict(line.split(":", 1) for line in Path(f"/proc/{pid}/status").read_text().splitlines() if ":" in line)
    return tuple(int(fields[name].split()[0]) / 1024 for name in ("VmRSS", "VmHWM"))  # type: ignore[return-value]


def run(folder: Path, frames: list, names: tuple[str, ...], qos_name: str, seconds: float, estimate: bool) -> None:
    domain_id = free_domain_id()
    out = folder / f"out_{qos_name}"
    params = {
        "cameras_file": str(folder / "cameras.yaml"),
        "output_dir": str(out),
        "image_qos": qos_name,
        "require_coverage": False,
        "write_report": False,
        "running_estimate": estimate,
    }
    collector = start("wand_calib_ros.nodes.collector", params, domain_id=domain_id, log=folder / f"{qos_name}.log")
    context = Context()
    rclpy.init(context=context, domain_id=domain_id)
    node = Node("benchmark_camera_drivers", context=context)
    qos = qos_profile_sensor_data if qos_name == "sensor_data" else QoSProfile(depth=10)
    publishers = {name: node.create_publisher(Image, f"/{name}/image_raw", qos) for name in names}
    received: dict[str, int] = {}

    def on_diagnostics(array: DiagnosticArray) -> None:
        for status in array.status:
            values = {v.key: v.value for v in status.values}
            if "received" in values:
                received[status.hardware_id] = int(values["received"])

    node.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, 10)
    client = node.create_client(Trigger, "/calibrate")
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and not all(p.get_subscription_count() for p in publishers.values()):
            time.sleep(0.05)
        client.wait_for_service(timeout_sec=30.0)
        time.sleep(1.0)
        cpu0, begin = _cpu_seconds(collector.pid), time.monotonic()
        period = 1.0 / FPS
        n_frames = int(seconds * FPS)
        published = 0
        for k in range(n_frames):
            target = begin + k * period
            delay = target - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            stamp = int(1e9 * (100 + k * period))
            for name in names:
                message = frames[k % len(frames)][name]
                message.header.stamp.sec, message.header.stamp.nanosec = divmod(stamp, 10**9)
                publishers[name].publish(message)
                published += 1
        elapsed = time.monotonic() - begin
        cpu = _cpu_seconds(collector.pid) - cpu0
        resident, peak = _memory_mb(collector.pid)
        settled = -1
        while settled != sum(received.values()):  # until two diagnostics in a row agree
            settled = sum(received.values())
            time.sleep(2.2)
        got = sum(received.values())
        rate = published / elapsed
        print(
            f"{qos_name:>11}: published {published} images in {elapsed:.1f} s ({rate:.0f}/s, "
            f"{rate * 1280 * 1024 / 1e6:.0f} MB/s); collector received {got} "
            f"({published - got} dropped, {100 * (published - got) / published:.2f} %), "
            f"collector CPU {100 * cpu / elapsed:.0f} % of one core, {resident:.0f} MB resident (peak {peak:.0f} MB)"
        )
        # The service's answer time, to a client that found it before (a GUI's, rqt's); then the
        # whole of a fresh `trigger /calibrate`, whose node first has to discover the service.
        began = time.perf_counter()
        response = client.call(Trigger.Request(), timeout_sec=300.0)
        latency = time.perf_counter() - began
        message = response.message if response is not None else "no answer"
        print(f"{'':>11}  /calibrate answered in {latency:.2f} s: {message[:110]}")
        began = time.perf_counter()
        call_trigger("/calibrate", 300.0, context)
        print(f"{'':>11}  again from a new client (discovery included): {time.perf_counter() - began:.2f} s")
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)
        spinner.join(timeout=5)
        code = stop(collector)
        print(f"{'':>11}  collector exit code {code}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=20.0, help="publishing time per run")
    parser.add_argument("--keep", type=Path, help="keep the collectors' output here (default: a temporary folder)")
    parser.add_argument("--drivers", choices=("default", "large-images"), help="run one transport set-up only")
    parser.add_argument("--no-estimate", action="store_true", help="collector with running_estimate off")
    args = parser.parse_args()
    if args.drivers is None:  # Fast DDS reads its profile once per process: one child per set-up
        for drivers in ("default", "large-images"):
            command = [sys.executable, __file__, "--seconds", str(args.seconds), "--drivers", drivers]
            command += ["--keep", str(args.keep / drivers)] if args.keep else []
            command += ["--no-estimate"] if args.no_estimate else []
            subprocess.run(command, check=True)
        return
    if args.drivers == "large-images":
        use_large_image_transport(os.environ)
    else:
        os.environ.pop("FASTRTPS_DEFAULT_PROFILES_FILE", None)  # the collector still loads its own
    estimate = "off" if args.no_estimate else "on"
    print(f"camera drivers on the {args.drivers} Fast DDS transport; the collector's running estimate {estimate}")
    mocap = mocap_scenario()
    scenario = dataclasses.replace(mocap, cameras=mocap.cameras[:4], min_views=2)
    names = scenario.rig.camera_names
    print(f"  rendering 150 frames x {len(names)} cameras at {scenario.rig.cameras[0].image_size} ...")
    recording = render_recording(scenario, 150, FPS, RenderOptions(), np.random.default_rng(0))
    frames: list[dict[str, Image]] = [{} for _ in range(150)]
    index = {stamp: k for k, stamp in enumerate(sorted({int(stamp) for _, stamp, _ in recording.frames}))}
    for camera, stamp, pixels in recording.frames:
        frames[index[int(stamp)]][camera] = array_to_image(pixels, stamp, camera)
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.keep or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        save_rig(scenario.rig, folder / "cameras.yaml")
        for qos_name in ("sensor_data", "reliable"):
            run(folder, frames, names, qos_name, args.seconds, not args.no_estimate)


if __name__ == "__main__":
    main()
