"""The calibrator node: ``/calibrate`` on what a collector persisted, results on topics and in files.

``/calibrate`` (std_srvs/Trigger) reads the collector's buffer file
(``output_dir/observations.csv``), checks its coverage, and runs the pipeline in
its own executor thread (diagnostics and images keep flowing). It answers at once
when a run is already in progress, and with what is missing or why the solve
failed otherwise; on success with per camera RMS, the wand-length RMS and the
result's path. It publishes per camera ``wand_calib/<cam>/camera_info``
(sensor_msgs/CameraInfo, in the camera's model) and ``wand_calib/<cam>/extrinsics``
(geometry_msgs/TransformStamped, parent = reference camera, or ``world_frame``
once a floor was set), both transient-local, ``wand_calib/markers``
(visualization_msgs/MarkerArray for RViz: the cameras' frustums and names, the newest wand
placements and the volume they cover, in the same parent frame; latched), the same transforms on ``/tf_static``
(tf2_msgs/TFMessage, latched like tf2's static broadcaster) whenever tf2_msgs is
importable (every ROS install; not the PyPI wheels), and writes ``result.yaml`` and ``camera_info/<cam>.yaml``
before it answers. The report (``report/index.html``, about a second of figures) is drawn after the answer,
in a thread of its own; the answer says where it will be and the log says when it is there (a calibration
that ends meanwhile is answered at once, its report drawn next). With ``commit_to_drivers`` it sends each camera's
CameraInfo to its driver's ``set_camera_info`` service, as ROS
camera_calibration's commit does.

``/refine`` (std_srvs/Trigger), after a ``/calibrate``: the frames the buffer gained since then are
judged for cameras that moved (the pairs' wand fits, as the collector's bump watch does); only those
cameras are re-estimated from the frames after the move (with ``refine_intrinsics`` also their k1, k2,
u0, v0), everything else held, and the result is written and published as ``/calibrate``'s.

It runs inside ``collector`` by default, or alone (``ros2 run wand_calib_ros
calibrator``) on the buffer file of a collector that runs elsewhere or has stopped.
"""

from __future__ import annotations

import os
import sys
import threading
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from geometry_msgs.msg import TransformStamped

try:  # any ROS install has tf2_msgs; the PyPI wheels do not (docs/live.md: "Camera poses on /tf_static")
    from tf2_msgs.msg import TFMessage
except ImportError:  # pragma: no cover - depends on the ROS install
    TFMessage = None
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.context import Context
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo
from sensor_msgs.srv import SetCameraInfo
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray

from wand_calib_ros.collection.buffer import BUFFER_FILE, has_rows
from wand_calib_ros.collection.floor import FLOOR_FILE, read_floor_frames
from wand_calib_ros.collection.job import (
    CalibrationFiles,
    refine_calibration,
    report_request,
    run_calibration,
    summary,
)
from wand_calib_ros.collection.recovery import backup_path
from wand_calib_ros.collection.report_drawer import DrawnReport, ReportDrawer
from wand_calib_ros.core.after.rig_scene import rig_scene
from wand_calib_ros.core.model.result import TIMING_MODES, CalibrationResult
from wand_calib_ros.core.model.rig import WandObservations
from wand_calib_ros.core.pipeline import CalibrationOptions
from wand_calib_ros.errors import WandCalibError
from wand_calib_ros.io.export import FORMATS
from wand_calib_ros.io.observations_csv import read_rig_observations
from wand_calib_ros.io.rig_yaml import load_camera_endpoints, load_rig
from wand_calib_ros.io.session_csv import EVENTS_FILE, append_event
from wand_calib_ros.nodes import messages
from wand_calib_ros.nodes.markers import markers_message
from wand_calib_ros.nodes.params import (
    COVERAGE,
    LATCHED,
    RIG,
    Param,
    SettingsError,
    coverage_thresholds,
    declare,
    existing_file,
    usage,
)
from wand_calib_ros.nodes.runner import run

PARAMS = (
    *RIG,
    *COVERAGE,
    Param("require_coverage", True, "refuse /calibrate until the coverage thresholds are met"),
    Param("write_report", True, "draw output_dir/report/index.html after each calibration (after its answer)"),
    Param("world_frame", "world", "parent frame of the published extrinsics once a floor was set (/set_floor)"),
    Param(
        "export_formats",
        "",
        "other tools' formats also written into output_dir/export/<format>/ (comma-separated: "
        + ", ".join(FORMATS)
        + ")",
    ),
    Param("refine_intrinsics", False, "/refine also re-estimates the moved cameras' k1, k2, u0 and v0"),
    Param("commit_to_drivers", False, "send the results to each camera driver's set_camera_info service"),
    Param("driver_timeout_s", 5.0, "how long to wait for a driver's set_camera_info (s)", 0.1, 600.0),
    Param(
        "time_offsets",
        "auto",
        "per camera time offsets: auto (estimated for free-running cameras, else when significant), estimate, fixed",
        choices=TIMING_MODES,
    ),
    Param(
        "rolling_shutter",
        "auto",
        "per camera rolling-shutter readout times: auto (estimated when significant), estimate, fixed",
        choices=TIMING_MODES,
    ),
)


#: The answer to a /calibrate the node's stop interrupted.
STOPPED = "the calibrator was stopped (Ctrl-C or SIGTERM) during the calibration; call /calibrate after a restart"
#: How long a stop waits for a report being drawn (ros2 launch escalates to SIGTERM after 5 s); a report
#: cut short leaves none of its files, and the calibration's own files are written before the answer.
REPORT_AT_STOP_S = 4.0


class CalibratorNode(Node):
    """``/calibrate`` on the persisted buffer; publishes and writes the result (module docstring)."""

    #: A solve occupies one thread; another answers "in progress", a third takes driver answers.
    EXECUTOR_THREADS = 3

    def __init__(
        self,
        *,
        before_calibrate: Callable[[], None] | None = None,
        after_calibrate: Callable[[CalibrationResult], None] | None = None,
        collector_values: dict[str, Any] | None = None,
        take: Callable[[], int] | None = None,
        **kwargs: Any,
    ) -> None:
        """
        Args:
            before_calibrate: called at the start of each /calibrate (the in-process collector
                stores what it still holds).
            after_calibrate: called with each successful result (the in-process collector shows
                its time offsets on /diagnostics).
            collector_values: the in-process collector's parameters: what this node's own section leaves
                at its defaults comes from them, and its ``output_dir`` is always the collector's (so that
                /calibrate reads what this rig's collector writes).
            take: the in-process collector's take (counted up by each /reset): a calibration of a take that a
                /reset cleared while it solved is neither published nor kept as the new take's.
            **kwargs: passed to :class:`rclpy.node.Node` (context, parameter_overrides, ...).
        """
        super().__init__("wand_calib_calibrator", **kwargs)
        values = declare(self, PARAMS, collector_values)
        if collector_values is not None and values["output_dir"] != collector_values["output_dir"]:
            self.get_logger().warning(
                f"output_dir {values['output_dir']} of {self.get_name()} is not its collector's: /calibrate reads "
                f"and writes the collector's {collector_values['output_dir']}"
            )
            values["output_dir"] = collector_values["output_dir"]
        cameras_file = existing_file(values, "cameras_file")
        self.rig = load_rig(cameras_file)
        self.endpoints = load_camera_endpoints(cameras_file)
        self.frame_ids = {name: endpoint.frame_id for name, endpoint in self.endpoints.items()}
        self.output_dir = Path(values["output_dir"]).expanduser()
        self.thresholds = coverage_thresholds(values) if values["require_coverage"] else None
        self.reports = ReportDrawer(self._said_report) if values["write_report"] else None
        self.exports = export_formats(values["export_formats"])
        self.world_frame = str(values["world_frame"])
        self.refine_intrinsics = bool(values["refine_intrinsics"])
        self.commit = bool(values["commit_to_drivers"])
        self.driver_timeout = float(values["driver_timeout_s"])
        self.options = CalibrationOptions(
            time_offsets=values["time_offsets"], rolling_shutter=values["rolling_shutter"]
        )
        self.before_calibrate = before_calibrate
        self.after_calibrate = after_calibrate
        self.take = take
        self._logger = self.get_logger()  # (also for the report drawer's thread, after the node is destroyed)
        self._running = threading.Lock()
        self._stopping = threading.Event()
        self._worker: threading.Thread | None = None
        self.result: CalibrationResult | None = None  # the last calibration (what /refine repairs)
        self._calibrated_through = -1  # the newest frame id that calibration used
        # Reentrant: a second /calibrate during a solve gets its "in progress" answer at once,
        # and driver answers arrive while the solve's thread waits for them.
        group = ReentrantCallbackGroup()
        self.create_service(Trigger, "calibrate", self._on_calibrate, callback_group=group)
        self.create_service(Trigger, "refine", self._on_refine, callback_group=group)
        self.info_publishers = {
            name: self.create_publisher(CameraInfo, f"wand_calib/{name}/camera_info", LATCHED)
            for name in self.rig.camera_names
        }
        self.extrinsics_publishers = {
            name: self.create_publisher(TransformStamped, f"wand_calib/{name}/extrinsics", LATCHED)
            for name in self.rig.camera_names
        }
        self.markers = self.create_publisher(MarkerArray, "wand_calib/markers", LATCHED)
        self.tf_static = self.create_publisher(TFMessage, "/tf_static", LATCHED) if TFMessage is not None else None
        if self.tf_static is None:
            self.get_logger().info("tf2_msgs is not installed: camera poses go to wand_calib/<cam>/extrinsics only")
        self.drivers = {  # only when committing: idle clients would list services no driver offers
            name: self.create_client(SetCameraInfo, endpoint.set_camera_info, callback_group=group)
            for name, endpoint in self.endpoints.items()
            if self.commit
        }
        self.get_logger().info(f"/calibrate reads {self.output_dir / BUFFER_FILE}")

    def _on_calibrate(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        return self._serve("/calibrate", self._calibrate, response)

    def _on_refine(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        return self._serve("/refine", self._refine, response)

    def _serve(
        self, service: str, work: Callable[[str], tuple[bool, str]], response: Trigger.Response
    ) -> Trigger.Response:
        """Run ``work`` in its own thread (so that a stop can still answer the caller); one at a time."""
        if not self._running.acquire(blocking=False):
            response.success, response.message = False, "a calibration is already running; try again when it ends"
            return response
        try:
            outcome: list[tuple[bool, str]] = []
            done = threading.Event()
            worker = threading.Thread(
                target=self._solve, args=(service, work, outcome, done), name=service, daemon=True
            )
            self._worker = worker
            worker.start()
            while not done.wait(0.05) and not self._stopping.is_set():  # the answer as soon as it is done
                pass
            worker.join(timeout=0.0 if self._stopping.is_set() else None)
            response.success, response.message = outcome[0] if outcome else (False, STOPPED)
        finally:
            self._running.release()
        self._log(service, response.success, response.message)
        return response

    def calibrate_now(self, source: str, done: Callable[[bool, str], None] | None = None) -> bool:
        """Start a calibration without a service call (the collector's auto_calibrate), logged under
        ``source``, ``done(success, answer)`` called at its end; False when one is already running."""
        if not self._running.acquire(blocking=False):
            return False

        def work() -> None:
            outcome: list[tuple[bool, str]] = []
            try:
                self._solve(source, self._calibrate, outcome)
            finally:
                self._running.release()
            success, answer = outcome[0] if outcome else (False, STOPPED)
            self._log(source, success, answer)
            if done is not None:
                done(success, answer)

        self._worker = threading.Thread(target=work, name=source, daemon=True)
        self._worker.start()
        return True

    def _log(self, source: str, success: bool, message: str) -> None:
        if self._stopping.is_set():  # no log line: the context is gone (a caller gets the answer)
            return
        if success:  # rclpy ties one severity to each logging call site
            self.get_logger().info(f"{source}: {message}")
        else:
            self.get_logger().warning(f"{source}: {message}")

    def _solve(
        self,
        service: str,
        work: Callable[[str], tuple[bool, str]],
        outcome: list[tuple[bool, str]],
        done: threading.Event | None = None,
    ) -> None:
        try:
            outcome.append(work(service))
        except Exception as error:  # a bug: still answer, so the caller does not wait forever
            self.get_logger().error(f"{service}: unexpected error\n{traceback.format_exc()}")
            outcome.append((False, f"unexpected error (please report): {error!r}"))
        finally:
            if done is not None:
                done.set()

    @property
    def working(self) -> bool:
        """Whether a calibration is still computing or its report drawn (a stop answered its caller but could
        not end it)."""
        drawing = self.reports is not None and self.reports.active
        return drawing or (self._worker is not None and self._worker.is_alive())

    def close(self) -> None:
        """At exit (Ctrl-C, SIGTERM): answer a /calibrate in progress before the node goes away, and give a
        report being drawn a few seconds to be written."""
        self._stopping.set()
        if self._running.acquire(timeout=5.0):
            self._running.release()
        if self.reports is not None and self.reports.busy:
            self._logger.info(f"stopping: waiting up to {REPORT_AT_STOP_S:.0f} s for the report being drawn")
            if not self.reports.wait(REPORT_AT_STOP_S):
                self._logger.warning("stopped before the report was written: wand-calib report draws it again")

    def _report(self, observations: WandObservations, files: CalibrationFiles, source: str) -> str:
        """Give the calibration just written to the report drawer; returns what the answer says of it."""
        if self.reports is None or self._stopping.is_set():
            return ""
        page = self.reports.submit(report_request(self.rig, observations, files, self.output_dir, source))
        return f"; report to follow in {page}"

    def _said_report(self, drawn: DrawnReport) -> None:
        """(From the drawer's thread.) Say that a report is ready, or why it failed."""
        if drawn.error is None:
            self._logger.info(drawn.line())
        else:
            self._logger.warning(drawn.line())

    def _calibrate(self, source: str) -> tuple[bool, str]:
        if self.before_calibrate is not None:
            self.before_calibrate()
        take = self.take() if self.take is not None else None
        path = self.output_dir / BUFFER_FILE
        if not path.exists() or not has_rows(path):
            return False, f"nothing collected yet in {path}: is the collector running and the wand in view?"
        try:
            observations = self._read_buffer(path)
            self.get_logger().info(f"calibrating {observations.uv.shape[0]} frames of {path}")
            floor = read_floor_frames(self.output_dir / FLOOR_FILE)  # from the collector's /set_floor
            result, files = run_calibration(
                self.rig,
                observations,
                self.output_dir,
                thresholds=self.thresholds,
                options=replace(self.options, floor_frames=floor),
                exports=self.exports,
            )
        except WandCalibError as error:
            return False, f"calibration failed: {error}"
        if self.take is not None and self.take() != take:  # a /reset cleared its take meanwhile
            kept = self._set_aside(files)
            return False, (
                f"/reset cleared the take this calibration was solving: its result is not published nor kept "
                f"as the new take's (its files are in {kept}); wave the wand and /calibrate again"
            )
        self.result, self._calibrated_through = result, int(observations.frames.max())
        ok, answer = self._publish(result, files, observations.uv, "calibrated", ())
        return ok, answer + self._report(observations, files, source)

    def _set_aside(self, files: CalibrationFiles) -> Path:
        """Move a calibration's files (result, camera_info, exports; its report is not drawn) out of ``output_dir``
        into a new ``output_dir/reset-<time>/``; returns it."""
        folder = backup_path(self.output_dir / "reset", "take")
        folder.unlink()  # (a free name: the files go into a folder of that name)
        folder.mkdir()
        written = [files.result, *files.camera_info, *files.exports]
        tops = {p.relative_to(self.output_dir).parts[0] for p in written if p.is_relative_to(self.output_dir)}
        for name in sorted(tops):
            os.replace(self.output_dir / name, folder / name)
        return folder

    def _read_buffer(self, path: Path) -> WandObservations:
        """The collector's buffer file as the rig's observations (FormatError naming the file and row)."""
        return read_rig_observations(path, self.rig)

    def _refine(self, source: str) -> tuple[bool, str]:
        if self.result is None:
            return False, "nothing to refine: no /calibrate since this node started (offline: wand-calib refine)"
        if self.before_calibrate is not None:
            self.before_calibrate()
        path = self.output_dir / BUFFER_FILE
        try:
            observations = self._read_buffer(path)
            new = observations.select_frames(observations.frames > self._calibrated_through)
            if new.frames.size == 0:
                return False, f"no frames since the last calibration in {path}: wave the wand, then /refine"
            refined = refine_calibration(
                self.rig,
                self.result,
                new,
                self.output_dir,
                intrinsics=self.refine_intrinsics,
            )
        except WandCalibError as error:
            return False, f"refine failed: {error}"
        if refined.result is None or refined.files is None:
            return True, f"no camera moved: the {new.frames.size} frames since the calibration agree with it"
        self.result, self._calibrated_through = refined.result, int(new.frames.max())
        ok, answer = self._publish(refined.result, refined.files, new.uv, "refined", refined.moved)
        done = f"re-estimated {', '.join(refined.moved)} from the {refined.frames} frames after the move"
        assert refined.after is not None  # (a camera moved)
        return ok, f"{'; '.join(refined.lines)}; {done}: {answer}{self._report(refined.after, refined.files, source)}"

    def _publish(
        self, result: CalibrationResult, files: CalibrationFiles, uv: Any, event: str, cameras: tuple[str, ...]
    ) -> tuple[bool, str]:
        """Publish a result (topics, /tf_static, the markers of the placements ``uv``, the collector's
        callback, the drivers), note it in the session's events (``event`` of ``cameras``) and say so."""
        if self._stopping.is_set():  # the node is going away: publish nothing
            return False, STOPPED
        stamp = self.get_clock().now().to_msg()
        for name in self.rig.camera_names:
            self.info_publishers[name].publish(messages.camera_info_message(result, name, stamp, self.frame_ids[name]))
            transform = messages.extrinsics_message(result, name, stamp, self.world_frame, self.frame_ids)
            self.extrinsics_publishers[name].publish(transform)
        frame = messages.parent_frame(result, self.world_frame, self.frame_ids)
        self.markers.publish(markers_message(rig_scene(result, self.rig.camera_names, uv), stamp, frame))
        if self.tf_static is not None and TFMessage is not None:
            transforms = messages.static_transforms(result, stamp, self.world_frame, self.frame_ids)
            self.tf_static.publish(TFMessage(transforms=transforms))
        if self.after_calibrate is not None:
            self.after_calibrate(result)
        answer = summary(result, files)
        append_event(self.output_dir / EVENTS_FILE, time.time(), event, "+".join(cameras), answer)
        if self.commit:
            failures = self._commit(result, stamp)
            if failures:
                return False, f"{answer}; but committing to the drivers failed: {'; '.join(failures)}"
            answer += f"; committed to {', '.join(self.rig.camera_names)}"
        return True, answer

    def _commit(self, result: CalibrationResult, stamp: Any) -> list[str]:
        """Send each camera's CameraInfo to its driver; returns what failed (empty: all committed)."""
        pending = {}
        failures = []
        for name, client in self.drivers.items():
            if not client.wait_for_service(timeout_sec=self.driver_timeout):
                failures.append(f"{name}: no service {self.resolve_service_name(client.srv_name)}")
                continue
            info = messages.camera_info_message(result, name, stamp, self.frame_ids[name])
            request = SetCameraInfo.Request(camera_info=info)
            pending[name] = client.call_async(request)
        for name, future in pending.items():
            done = threading.Event()
            future.add_done_callback(lambda _, d=done: d.set())
            if not done.wait(self.driver_timeout):
                future.cancel()
                failures.append(f"{name}: {self.resolve_service_name(self.drivers[name].srv_name)} did not answer")
            elif not future.result().success:
                failures.append(f"{name}: {future.result().status_message}")
        return failures


def export_formats(text: str) -> tuple[str, ...]:
    """The ``export_formats`` parameter as format names (SettingsError naming an unknown one)."""
    names = tuple(name.strip() for name in text.split(",") if name.strip())
    unknown = [name for name in names if name not in FORMATS]
    if unknown:
        raise SettingsError(
            f"parameter export_formats: unknown format(s) {', '.join(unknown)}; known: {', '.join(FORMATS)}"
        )
    return names


def build(context: Context, args: Sequence[str] = ()) -> list[Node]:
    """A calibrator on its own (on the buffer file of a collector elsewhere)."""
    return [CalibratorNode(context=context)]


def main(argv: Sequence[str] | None = None) -> int:
    """``ros2 run wand_calib_ros calibrator --ros-args -p cameras_file:=... -p output_dir:=...``"""
    return run("calibrator", build, argv, help_text=usage("calibrator", __doc__, ("wand_calib_calibrator", PARAMS)))


if __name__ == "__main__":
    sys.exit(main())
