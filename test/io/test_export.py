"""Exports read back by the other tools' own code project exactly as this package does."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import tomllib
import yaml

from wand_calib_ros.cli import main
from wand_calib_ros.core.model.camera_model import project
from wand_calib_ros.core.model.geometry import Pose
from wand_calib_ros.io.errors import ExportError
from wand_calib_ros.io.export import export
from wand_calib_ros.io.export.cameras import ExportedCamera
from wand_calib_ros.io.result_yaml import camera_info_dict
from wand_calib_ros.sim.scenarios import SCENARIOS

#: mixed3 with plumb_bob lenses: a fisheye and two plumb_bob cameras in one file.
RIGS = ["mixed3", "ring6", "mixed3:plumb_bob"]


def _cameras(name: str) -> list[ExportedCamera]:
    scenario = SCENARIOS[name.split(":")[0]](pinhole=True) if name.endswith(":plumb_bob") else SCENARIOS[name]()
    return [ExportedCamera(c.spec.name, c.model, c.pose) for c in scenario.cameras]


def _points_seen_by(camera: ExportedCamera, rng: np.random.Generator, n: int = 200) -> np.ndarray:
    """(n, 3) reference-frame points within 60 deg of the camera's axis, 0.5-5 m away."""
    theta, phi = rng.uniform(0, np.radians(60), n), rng.uniform(0, 2 * np.pi, n)
    rays = np.column_stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])
    in_camera = rays * rng.uniform(500, 5000, n)[:, None]
    return (in_camera - camera.pose.translation) @ camera.pose.rotation  # X_ref = R^T (X_cam - T)


def _in_image(camera: ExportedCamera, points: np.ndarray) -> np.ndarray:
    """(N,) points in front of the camera that it images inside its image."""
    uv = _ours(camera, points)
    size = np.asarray(camera.model.image_size)
    return (camera.pose.apply(points)[:, 2] > 0) & np.all((uv >= 0) & (uv <= size - 1), axis=1)


def _ours(camera: ExportedCamera, points: np.ndarray) -> np.ndarray:
    return project(camera.model, camera.pose.apply(points))


@pytest.mark.parametrize("rig", RIGS)
def test_opencv_file_storage_projects_with_cv2_fisheye_as_we_do(tmp_path: Path, rig: str) -> None:
    cameras = _cameras(rig)
    paths = export(cameras, "opencv", tmp_path)
    rng = np.random.default_rng(0)
    for camera, path in zip(cameras, paths, strict=True):
        storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
        k, d = storage.getNode("K").mat(), storage.getNode("D").mat()
        rvec, t, r = storage.getNode("rvec").mat(), storage.getNode("T").mat(), storage.getNode("R").mat()
        kind = storage.getNode("camera_model").string()
        assert kind == ("pinhole" if camera.model.is_pinhole else "fisheye")
        if camera.model.is_pinhole:
            assert storage.getNode("distortion_model").string() == camera.model.distortion_model
        assert storage.getNode("reference_camera").string() == cameras[0].name
        assert int(storage.getNode("image_width").real()) == camera.model.image_size[0]
        storage.release()
        assert np.allclose(cv2.Rodrigues(rvec)[0], r, atol=1e-12)
        points = _points_seen_by(camera, rng)
        opencv_project = cv2.projectPoints if kind == "pinhole" else cv2.fisheye.projectPoints
        theirs, _ = opencv_project(points.reshape(-1, 1, 3), rvec, t, k, d)
        assert np.max(np.abs(theirs.reshape(-1, 2) - _ours(camera, points))) < 1e-6


def _triangulate(calibration: dict, keys: list[str], pixels: list[np.ndarray]) -> np.ndarray:
    """Linear triangulation from undistorted normalised points, as aniposelib's triangulate does."""
    rows = []
    for key, uv in zip(keys, pixels, strict=True):
        cam = calibration[key]
        matrix, dist = np.array(cam["matrix"]), np.array(cam["distortions"])
        undistort = cv2.fisheye.undistortPoints if cam["fisheye"] else cv2.undistortPointsIter
        criteria = () if cam["fisheye"] else (None, None, (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12))
        normalised = undistort(uv.reshape(-1, 1, 2), matrix, dist, *criteria).reshape(-1, 2)
        extrinsic = np.hstack([cv2.Rodrigues(np.array(cam["rotation"]))[0], np.array(cam["translation"])[:, None]])
        rows.append((normalised, extrinsic))
    out = []
    for p in range(rows[0][0].shape[0]):
        a = np.concatenate([[x[p, 0] * e[2] - e[0], x[p, 1] * e[2] - e[1]] for x, e in rows])
        _, _, vt = np.linalg.svd(a)
        out.append(vt[-1, :3] / vt[-1, 3])
    return np.array(out)


@pytest.mark.parametrize("rig", RIGS)
def test_anipose_toml_projects_and_triangulates_the_wand_as_we_do(tmp_path: Path, rig: str) -> None:
    cameras = _cameras(rig)
    (path,) = export(cameras, "anipose", tmp_path)
    calibration = tomllib.loads(path.read_text())
    keys = sorted(k for k in calibration if k != "metadata")  # aniposelib's load order
    assert [calibration[k]["name"] for k in keys] == [c.name for c in cameras]
    assert calibration["metadata"]["units"] == "mm"
    assert [calibration[k]["fisheye"] for k in keys] == [not c.model.is_pinhole for c in cameras]
    rng = np.random.default_rng(1)
    for key, camera in zip(keys, cameras, strict=True):
        entry = calibration[key]
        points = _points_seen_by(camera, rng)
        opencv_project = cv2.fisheye.projectPoints if entry["fisheye"] else cv2.projectPoints
        theirs, _ = opencv_project(  # aniposelib's FisheyeCamera.project (Camera.project for pinholes)
            points.reshape(-1, 1, 3),
            np.array(entry["rotation"]),
            np.array(entry["translation"]),
            np.array(entry["matrix"]),
            np.array(entry["distortions"]),
        )
        assert np.max(np.abs(theirs.reshape(-1, 2) - _ours(camera, points))) < 1e-6
    # A held-out wand (600 mm) seen by the first two cameras triangulates to its length from the TOML alone.
    middle = _points_seen_by(cameras[0], rng, 100)
    direction = rng.normal(size=(100, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    ends = [middle - 300 * direction, middle + 300 * direction]
    pixels = [[_ours(cameras[c], end) for c in (0, 1)] for end in ends]
    seen = np.all([_in_image(cameras[c], end) for end in ends for c in (0, 1)], axis=0)  # both see both ends
    a, c = (_triangulate(calibration, keys[:2], [p[seen] for p in end]) for end in pixels)
    assert seen.sum() > 20 and np.max(np.abs(np.linalg.norm(c - a, axis=1) - 600.0)) < 0.1


def _kalibr_project(entry: dict, points_in_camera: np.ndarray) -> np.ndarray:
    """Kalibr's pinhole camera with equidistant or radtan distortion (its documented models)."""
    fu, fv, pu, pv = entry["intrinsics"]
    x, y, z = points_in_camera.T
    if entry["distortion_model"] == "radtan":
        p1, p2 = entry["distortion_coeffs"][2:]
        a, b = x / z, y / z
        r2 = a * a + b * b
        radial = 1 + entry["distortion_coeffs"][0] * r2 + entry["distortion_coeffs"][1] * r2 * r2
        xd = a * radial + 2 * p1 * a * b + p2 * (r2 + 2 * a * a)
        yd = b * radial + p1 * (r2 + 2 * b * b) + 2 * p2 * a * b
        return np.column_stack([fu * xd + pu, fv * yd + pv])
    k1, k2, k3, k4 = entry["distortion_coeffs"]
    r = np.hypot(x, y)
    theta = np.arctan2(r, z)
    theta_d = theta * (1 + k1 * theta**2 + k2 * theta**4 + k3 * theta**6 + k4 * theta**8)
    scale = np.where(r > 0, theta_d / np.maximum(r, 1e-300), 1.0)
    return np.column_stack([fu * x * scale + pu, fv * y * scale + pv])


@pytest.mark.parametrize("rig", RIGS)
def test_kalibr_camchain_field_by_field(tmp_path: Path, rig: str) -> None:
    cameras = _cameras(rig)
    (path,) = export(cameras, "kalibr", tmp_path)
    chain = yaml.safe_load(path.read_text())
    assert list(chain) == [f"cam{i}" for i in range(len(cameras))]
    rng = np.random.default_rng(2)
    pose_of_previous = Pose.identity()  # cam0 is the reference
    for index, camera in enumerate(cameras):
        entry = chain[f"cam{index}"]
        kind = "radtan" if camera.model.is_pinhole else "equidistant"
        assert entry["camera_model"] == "pinhole" and entry["distortion_model"] == kind
        assert len(entry["intrinsics"]) == 4 and len(entry["distortion_coeffs"]) == 4
        assert entry["resolution"] == list(camera.model.image_size)
        assert entry["rostopic"] == f"/{camera.name}/image_raw"
        if index == 0:
            assert "T_cn_cnm1" not in entry
            pose = Pose.identity()
        else:
            t = np.array(entry["T_cn_cnm1"])
            assert t.shape == (4, 4) and np.allclose(t[3], [0, 0, 0, 1])
            pose = Pose(t[:3, :3], t[:3, 3] * 1000.0).compose(pose_of_previous)  # metres -> mm, chained
        assert np.allclose(pose.rotation, camera.pose.rotation, atol=1e-12)
        assert np.allclose(pose.translation, camera.pose.translation, atol=1e-9)
        pose_of_previous = pose
        points = _points_seen_by(camera, rng)
        assert np.max(np.abs(_kalibr_project(entry, camera.pose.apply(points)) - _ours(camera, points))) < 1e-6


def test_kalibr_refuses_a_plumb_bob_k3_by_name(tmp_path: Path) -> None:
    cameras = _cameras("mixed3:plumb_bob")
    model = cameras[1].model
    with_k3 = model.with_intrinsic_vector(model.intrinsic_vector() + np.r_[0, 0, 0, 0.01 * model.k[0], 0, 0, 0])
    cameras[1] = ExportedCamera(cameras[1].name, with_k3, cameras[1].pose)
    with pytest.raises(
        ExportError, match=r"camera cam1: Kalibr's radtan model has k1, k2, p1, p2 only and its k3 is 0\.01"
    ):
        export(cameras, "kalibr", tmp_path)
    assert not list(tmp_path.iterdir())


def test_camera_info_export_is_the_ros_document(tmp_path: Path) -> None:
    cameras = _cameras("mixed3")
    paths = export(cameras, "camera_info", tmp_path)
    for camera, path in zip(cameras, paths, strict=True):
        assert yaml.safe_load(path.read_text()) == camera_info_dict(camera.name, camera.model)


def test_the_export_command_writes_a_result_in_each_format(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = tmp_path / "run"
    assert main(["-q", "simulate", "mixed", "--seed", "2", "--noise", "0.5", "--out", str(folder)]) == 0
    argv = ["--cameras", str(folder / "cameras.yaml"), "--observations", str(folder / "observations.csv")]
    assert main(["-q", "calibrate", *argv, "--output", str(folder / "result.yaml")]) == 0
    for name, files in (("opencv", 2), ("anipose", 1), ("kalibr", 1), ("camera_info", 2)):
        out = tmp_path / name
        assert main(["export", "--result", str(folder / "result.yaml"), "--format", name, "--out", str(out)]) == 0
        assert len(list(out.iterdir())) == files
    capsys.readouterr()
    code = main(["export", "--result", str(folder / "result.yaml"), "--format", "dlt", "--out", str(tmp_path / "d")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "camera cam0: DLT coefficients describe distortion-free pinhole cameras" in err
    assert "\n" not in err and "Traceback" not in err and not (tmp_path / "d").exists()
    (tmp_path / "plain").write_text("a file\n")
    capsys.readouterr()
    code = main(
        ["export", "--result", str(folder / "result.yaml"), "--format", "kalibr", "--out", str(tmp_path / "plain")]
    )
    assert code == 2 and "plain is a file, not a folder" in capsys.readouterr().err


def test_dlt_coefficients_of_pinhole_cameras_project_as_we_do_with_the_bottom_left_origin(tmp_path: Path) -> None:
    from wand_calib_ros.core.model.known_intrinsics import from_pinhole_radtan
    from wand_calib_ros.io.export.dlt import MAX_PINHOLE_ERROR_PX

    rng = np.random.default_rng(3)
    cameras, at_origin = [], []
    offset = np.array([100.0, 200.0, -2500.0])  # a world frame: X_ref = X_world + offset
    for index, camera in enumerate(_cameras("conventional")):  # the poses of a rig, pinhole lenses
        K = np.array([[900.0 + 50 * index, 0.0, 630.0], [0.0, 905.0 + 50 * index, 515.0], [0.0, 0.0, 1.0]])
        model, _ = from_pinhole_radtan(K, np.zeros(4), camera.model.m, (1280, 1024))
        world_pose = Pose(camera.pose.rotation, camera.pose.rotation @ offset + camera.pose.translation)
        cameras.append(ExportedCamera(camera.name, model, world_pose))
        at_origin.append(ExportedCamera(camera.name, model, camera.pose))
    with pytest.raises(ExportError, match="cam0: DLT coefficients cannot describe a camera whose focal plane holds"):
        export(at_origin, "dlt", tmp_path)  # the reference frame: cam0 sits at its origin
    (path,) = export(cameras, "dlt", tmp_path)
    table = np.loadtxt(path, delimiter=",")
    assert table.shape == (11, len(cameras))
    for c, camera in enumerate(cameras):
        points = _points_seen_by(camera, rng)
        points = points[_in_image(camera, points)]
        L = table[:, c]
        w = points @ L[8:11] + 1.0
        u = (points @ L[0:3] + L[3]) / w
        v = (points @ L[4:7] + L[7]) / w
        ours = _ours(camera, points)
        expected = np.column_stack([ours[:, 0], camera.model.image_size[1] - ours[:, 1]])
        assert len(points) > 50
        assert np.abs(np.column_stack([u, v]) - expected).max() < MAX_PINHOLE_ERROR_PX


def test_dlt_refuses_a_fisheye_by_name(tmp_path: Path) -> None:
    with pytest.raises(ExportError, match=r"camera cam0: DLT coefficients describe distortion-free pinhole cameras"):
        export(_cameras("mixed"), "dlt", tmp_path / "mixed")
    with pytest.raises(ExportError, match=r"camera cam0: .*differs from any pinhole by \d+\.\d px"):
        export(_cameras("conventional"), "dlt", tmp_path / "conventional")
    assert not (tmp_path / "mixed").exists() and not (tmp_path / "conventional").exists()


@pytest.mark.parametrize("rig", RIGS)
def test_aniposelib_itself_loads_our_toml_projects_and_triangulates_the_wand_as_we_do(tmp_path: Path, rig: str) -> None:
    aniposelib = pytest.importorskip("aniposelib")  # installed by make setup (without its GUI/jax extras)

    cameras = _cameras(rig)
    (path,) = export(cameras, "anipose", tmp_path)
    group = aniposelib.cameras.CameraGroup.load(str(path))
    assert group.get_names() == [c.name for c in cameras]
    rng = np.random.default_rng(4)
    for index, camera in enumerate(cameras):
        points = _points_seen_by(camera, rng)
        theirs = group.cameras[index].project(points).reshape(-1, 2)
        assert np.max(np.abs(theirs - _ours(camera, points))) < 1e-6
    # A held-out 600 mm wand seen by the first two cameras: aniposelib's own triangulation.
    middle = _points_seen_by(cameras[0], rng, 200)
    direction = rng.normal(size=(200, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    ends = [middle - 300 * direction, middle + 300 * direction]
    seen = np.all([_in_image(cameras[c], end) for end in ends for c in (0, 1)], axis=0)
    triangulated = []
    for end in ends:
        pixels = np.full((len(cameras), int(seen.sum()), 2), np.nan)
        for c in (0, 1):
            pixels[c] = _ours(cameras[c], end[seen])
        triangulated.append(group.triangulate(pixels, undistort=True, progress=False))
    lengths = np.linalg.norm(triangulated[1] - triangulated[0], axis=1)
    assert seen.sum() > 20 and np.max(np.abs(lengths - 600.0)) < 0.1
