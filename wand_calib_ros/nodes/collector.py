"""The live calibration node: image topics in, calibration out.

One node subscribes to every camera's image topic (sensor-data QoS), runs the
LED detector, time-synchronises the detections into frames, keeps them in the
persisted buffer and tracks coverage (published on ``/diagnostics`` at 1 Hz).
``/calibrate`` (std_srvs/Trigger) solves in its own executor thread and publishes per
camera ``wand_calib/<cam>/camera_info`` (transient local, ``equidistant``) and
``wand_calib/<cam>/extrinsics`` (geometry_msgs/TransformStamped, parent = reference camera), and
writes ``result.yaml`` and camera_info YAML files into ``output_dir``;
``/reset`` clears the buffer after backing it up. Only message and parameter
translation lives here: the work is done by the core, detection and
collection packages.
"""

from __future__ import annotations

import logging
import sys
import threading
from pathlib import Path

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import TransformStamped
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import CameraInfo, Image
from std_srvs.srv import Trigger

from wand_calib_ros.collection.buffer import ObservationBuffer
from wand_calib_ros.collection.coverage import CoverageThresholds, CoverageTracker
from wand_calib_ros.collection.sync import FrameSynchroniser
from wand_calib_ros.core.camera_model import to_opencv_fisheye
from wand_calib_ros.core.pipeline import calibrate
from wand_calib_ros.core.result import CalibrationResult
from wand_calib_ros.core.rig import WandObservations
from wand_calib_ros.detection.blobs import BlobOptions
from wand_calib_ros.detection.errors import ImageError
from wand_calib_ros.detection.recording import OnlineLabeller, detect_image, nominal_model
from wand_calib_ros.detection.wand import WandOptions
from wand_calib_ros.errors import WandCalibError
from wand_calib_ros.io.result_yaml import write_camera_infos, write_result
from wand_calib_ros.io.rig_yaml import load_rig

_LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE)


def image_to_array(message: Image) -> np.ndarray:
    """The pixels of a sensor_msgs/Image as a numpy array (no copy for 8-bit data)."""
    data = np.frombuffer(message.data, dtype=np.uint8)
    height, step = message.height, message.step
    rows = data[: height * step].reshape(height, step)
    if message.encoding == "mono16":
        return rows.view(">u2" if message.is_bigendian else "<u2")[:, : message.width]
    channels = {"bgr8": 3, "rgb8": 3, "bgra8": 4, "rgba8": 4}.get(message.encoding, 1)
    pixels = rows[:, : message.width * channels]
    return pixels.reshape(height, message.width, channels) if channels > 1 else pixels


def camera_info_message(result: CalibrationResult, name: str, stamp: object) -> CameraInfo:
    """sensor_msgs/CameraInfo (``equidistant``) exactly equivalent to a calibrated camera."""
    model = result.camera(name).model
    opencv = to_opencv_fisheye(model)
    info = CameraInfo()
    info.header.stamp = stamp
    info.header.frame_id = name
    info.width, info.height = model.image_size
    info.distortion_model = "equidistant"
    info.d = [float(v) for v in opencv.distortion]
    info.k = [float(v) for v in opencv.camera_matrix.ravel()]
    info.r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    info.p = [float(v) for v in np.hstack([opencv.camera_matrix, np.zeros((3, 1))]).ravel()]
    return info


def extrinsics_message(result: CalibrationResult, name: str, stamp: object) -> TransformStamped:
    """geometry_msgs/TransformStamped of a camera in the reference camera's frame (metres).

    The transform maps the camera's frame into the reference camera's frame
    (ROS convention: parent = reference camera, child = this camera), i.e. the
    inverse of the result's X_cam = R X_ref + T.
    """
    pose = result.camera(name).pose
    rotation = pose.rotation.T
    translation = pose.center / 1000.0
    x, y, z, w = Rotation.from_matrix(rotation).as_quat()
    message = TransformStamped()
    message.header.stamp = stamp
    message.header.frame_id = result.reference_camera
    message.child_frame_id = name
    message.transform.translation.x, message.transform.translation.y, message.transform.translation.z = (
        float(v) for v in translation
    )
    message.transform.rotation.x, message.transform.rotation.y = float(x), float(y)
    message.transform.rotation.z, message.transform.rotation.w = float(z), float(w)
    return message


class CollectorNode(Node):
    """Detection, synchronisation, buffer, coverage and /calibrate in one node."""

    def __init__(self, **kwargs: object) -> None:
        super().__init__("wand_calib_collector", **kwargs)
        cameras_file = self._parameter("cameras_file", "", "rig description (cameras.yaml contract)")
        output_dir = Path(self._parameter("output_dir", "wand_calib_output", "where observations and results go"))
        tolerance_ms = self._parameter("sync_tolerance_ms", 5.0, "images closer in time form one frame (ms)")
        capacity = self._parameter("buffer_capacity", 20000, "frames kept before thinning")
        min_placements = self._parameter("min_placements", 100, "complete views per camera needed")
        image_qos = self._parameter("image_qos", "sensor_data", "sensor_data (best effort) or reliable (bag replay)")
        if not cameras_file:
            raise WandCalibError("parameter cameras_file is required (the rig description)")
        self.rig = load_rig(cameras_file)
        self.output_dir = output_dir
        self.buffer = ObservationBuffer.open(output_dir / "observations.csv", self.rig, capacity=int(capacity))
        self.coverage = CoverageTracker(self.rig, CoverageThresholds(min_placements=int(min_placements)))
        for uv in self.buffer.uv:
            self.coverage.add(uv)
        self.sync = FrameSynchroniser(self.rig.camera_names, slop_ns=int(float(tolerance_ms) * 1e6))
        self.wand_options = WandOptions(ratio=self.rig.wand.L1 / self.rig.wand.L2)
        self.models = {c.name: nominal_model(c) for c in self.rig.cameras}
        self.labellers = {name: OnlineLabeller() for name in self.rig.camera_names}
        self.lock = threading.Lock()
        self.solving = threading.Event()
        self.result: CalibrationResult | None = None
        # One group per camera: cameras are detected in parallel, each camera's images in order
        # (the A/C labeller follows the wand from one image to the next).
        for spec in self.rig.cameras:
            self.create_subscription(
                Image,
                f"/{spec.name}/image_raw",
                lambda m, n=spec.name: self._on_image(n, m),
                qos_profile_sensor_data if image_qos == "sensor_data" else QoSProfile(depth=100),
                callback_group=MutuallyExclusiveCallbackGroup(),
            )
        # /calibrate may be called again while it solves (and answers "in progress"); diagnostics
        # have their own group so they keep flowing during a solve.
        self.create_service(Trigger, "calibrate", self._on_calibrate, callback_group=ReentrantCallbackGroup())
        self.create_service(Trigger, "reset", self._on_reset, callback_group=MutuallyExclusiveCallbackGroup())
        self.info_publishers = {
            spec.name: self.create_publisher(CameraInfo, f"wand_calib/{spec.name}/camera_info", _LATCHED)
            for spec in self.rig.cameras
        }
        self.extrinsics_publishers = {
            spec.name: self.create_publisher(TransformStamped, f"wand_calib/{spec.name}/extrinsics", _LATCHED)
            for spec in self.rig.cameras
        }
        self.diagnostics = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_timer(1.0, self._publish_diagnostics, callback_group=MutuallyExclusiveCallbackGroup())
        self.get_logger().info(
            f"collecting {', '.join(self.rig.camera_names)} into {self.buffer.path} ({len(self.buffer.frames)} resumed)"
        )

    def _parameter(self, name: str, default: object, description: str) -> object:
        return self.declare_parameter(name, default, ParameterDescriptor(description=description)).value

    def _on_image(self, camera: str, message: Image) -> None:
        stamp = message.header.stamp.sec * 10**9 + message.header.stamp.nanosec
        points = None
        try:
            _, detection = detect_image(
                image_to_array(message), message.encoding, BlobOptions(), self.wand_options, self.models[camera]
            )
        except (ImageError, ValueError):
            detection = None
        with self.lock:
            if detection is not None and detection.points is not None:
                points = self.labellers[camera].update(stamp, detection)
            for frame in self.sync.add(camera, stamp, points):
                if self.buffer.offer(frame.uv):
                    self.coverage.add(frame.uv)

    def _publish_diagnostics(self) -> None:
        with self.lock:
            status = self.coverage.status()
            frames = len(self.buffer.frames)
        array = DiagnosticArray()
        array.header.stamp = self.get_clock().now().to_msg()
        for camera in status.cameras:
            entry = DiagnosticStatus(name=f"wand_calib: {camera.name}", hardware_id=camera.name)
            entry.level = DiagnosticStatus.OK if camera.ok else DiagnosticStatus.WARN
            entry.message = "ready" if camera.ok else "; ".join(camera.missing)
            entry.values = [
                KeyValue(key="placements", value=str(camera.placements)),
                KeyValue(key="image_coverage_percent", value=f"{100 * camera.image_fraction:.0f}"),
                KeyValue(key="max_theta_deg", value=f"{camera.max_theta_deg:.1f}"),
            ]
            array.status.append(entry)
        rig = DiagnosticStatus(name="wand_calib: rig", hardware_id="rig")
        rig.level = DiagnosticStatus.OK if status.ready else DiagnosticStatus.WARN
        rig.message = f"ready ({frames} frames)" if status.ready else " | ".join(status.messages())
        array.status.append(rig)
        self.diagnostics.publish(array)

    def _on_calibrate(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        # A reentrant group: the solve runs in this executor thread while the image, timer and
        # other service callbacks keep running in the others.
        with self.lock:
            if self.solving.is_set():
                response.success, response.message = False, "a calibration is already running"
                return response
            self.solving.set()
            for frame in self.sync.flush_all():
                if self.buffer.offer(frame.uv):
                    self.coverage.add(frame.uv)
            observations = self.buffer.observations()
        try:
            response.success, response.message = self._solve(observations)
        finally:
            self.solving.clear()
        return response

    def _solve(self, observations: WandObservations) -> tuple[bool, str]:
        try:
            result = calibrate(self.rig, observations)
        except WandCalibError as error:
            return False, f"calibration failed: {error}"
        self.output_dir.mkdir(parents=True, exist_ok=True)
        write_result(result, self.output_dir / "result.yaml")
        write_camera_infos(result, self.output_dir / "camera_info")
        stamp = self.get_clock().now().to_msg()
        for name, publisher in self.info_publishers.items():
            publisher.publish(camera_info_message(result, name, stamp))
            self.extrinsics_publishers[name].publish(extrinsics_message(result, name, stamp))
        self.result = result
        summary = ", ".join(f"{c.name} {c.rms_reprojection_px:.2f} px" for c in result.cameras)
        return True, f"RMS {summary}; wand {result.wand_length_rms_mm:.2f} mm RMS; {self.output_dir / 'result.yaml'}"

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        with self.lock:
            backup = self.buffer.reset()
            self.coverage = CoverageTracker(self.rig, self.coverage.thresholds)
        response.success, response.message = True, f"buffer cleared; backup {backup}"
        return response


def main(argv: list[str] | None = None) -> int:
    """``ros2 run wand_calib_ros collector --ros-args -p cameras_file:=...``"""
    logging.basicConfig(level=logging.WARNING)
    rclpy.init(args=argv if argv is not None else sys.argv)
    executor = MultiThreadedExecutor(num_threads=4)
    try:
        node = CollectorNode()
    except WandCalibError as error:
        print(f"collector: error: {error}", file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    executor.add_node(node)
    try:
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
