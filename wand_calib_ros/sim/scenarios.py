"""Synthetic rigs with known truth: the paper's simulation and its real setups.

Every scenario gives the rig description a user would write (nominal focal
length, pixel size, field of view), the true cameras behind it, and wand
placements drawn in a volume and imaged with Gaussian pixel noise. Randomness
comes only from the generator passed in.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.initialise.intrinsics_init import PROJECTIONS
from wand_calib_ros.core.model.camera_model import PLUMB_BOB, CameraModel, from_opencv_pinhole, project
from wand_calib_ros.core.model.geometry import Pose, rotation_from_rotvec
from wand_calib_ros.core.model.rig import CameraSpec, RigSpec, WandObservations, WandSpec

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class TrueCamera:
    """A simulated camera: what the user declares and what it really is."""

    spec: CameraSpec
    model: CameraModel
    pose: Pose
    true_max_view_angle: float  # rad; rays beyond it do not reach the sensor


@dataclass(frozen=True, eq=False)
class Scenario:
    """A simulated rig and the volume the wand is waved in.

    Attributes:
        name: scenario name.
        wand: wand lengths.
        cameras: true cameras (cameras[0] is the reference, pose identity).
        volume: (2, 3) min and max corner of the wand-centre volume, reference frame, mm.
        n_placements: placements to generate.
        min_views: placements must be seen completely by at least this many cameras
            (None: by every camera).
        led_cone_deg: half-angle of the LEDs' emission cone around the wand's facing
            direction (None: visible from everywhere).
        view_rates: per camera, the probability that a view it could have had was recorded (digitised,
            not occluded): a sparse take, as a user digitising a video has it (None: every view).
        marker_loss: the probability that a recorded view lacks each of its markers (occluded, not
            digitised): views of some markers only.
        floor: (3, 3) the room's floor in the reference frame: a point on it under the volume's centre,
            its normal (up, towards the cameras) and the room's x direction on it (None: no floor).
    """

    name: str
    wand: WandSpec
    cameras: tuple[TrueCamera, ...]
    volume: FloatArray
    n_placements: int
    min_views: int | None = None
    led_cone_deg: float | None = None
    view_rates: tuple[float, ...] | None = None
    marker_loss: float = 0.0
    floor: FloatArray | None = None

    @property
    def rig(self) -> RigSpec:
        return RigSpec(self.wand, tuple(c.spec for c in self.cameras))


@dataclass(frozen=True, eq=False)
class SimulatedData:
    """Observations with the truth behind them.

    Attributes:
        observations: noisy pixels of the placements.
        wand_a: (P, 3) true A per placement, reference frame, mm.
        wand_direction: (P, 3) true unit A->C direction.
        noise_px: standard deviation of the pixel noise.
        facing: (P, 3) unit direction the LEDs face (matters with an emission cone).
    """

    observations: WandObservations
    wand_a: FloatArray
    wand_direction: FloatArray
    noise_px: float
    facing: FloatArray


def fit_radial(projection: str | Callable[[FloatArray], FloatArray], focal_mm: float, max_angle: float) -> FloatArray:
    """(5,) k1..k5 fitted by least squares to a projection over [0, max_angle].

    Args:
        projection: a name from the paper's five projections, or r(theta)/f as a callable.
        focal_mm: focal length, mm.
        max_angle: upper end of the fit, rad.
    """
    theta = np.linspace(0.0, max_angle, 400)[1:]
    target = PROJECTIONS[projection](focal_mm, theta) if isinstance(projection, str) else focal_mm * projection(theta)
    design = theta[:, None] ** (2 * np.arange(5) + 1)
    return np.linalg.lstsq(design, target, rcond=None)[0]


def equisolid_taylor(focal_mm: float) -> FloatArray:
    """(5,) Taylor coefficients of 2 f sin(theta/2): within 2e-8 mm (4e-6 px at 5.6 um) up to 95 degrees."""
    return focal_mm * np.array([1.0, -1.0 / 24, 1.0 / 1920, -1.0 / 322560, 1.0 / 92897280])


def _euler_pose(euler_deg: tuple[float, float, float], translation: tuple[float, float, float]) -> Pose:
    """The pose turned about the fixed x, y, then z axes by ``euler_deg`` (R = Rz Ry Rx)."""
    rotation = np.eye(3)
    for axis, angle in enumerate(np.radians(euler_deg)):
        rotation = rotation_from_rotvec(angle * np.eye(3)[axis]) @ rotation
    return Pose(rotation, np.array(translation))


def paper_fisheye_scenario(
    *,
    true_focal_mm: float = 2.0,
    principal_point: tuple[float, float] = (310.0, 250.0),
    nominal_focal_mm: float = 1.8,
    n_cameras: int = 2,
    n_placements: int = 300,
) -> Scenario:
    """The paper's simulation (Section IV-A).

    640x480 px, 5.6 um pixels, 185 degree lenses (true lens: equisolid with
    ``true_focal_mm``; declared nominal focal ``nominal_focal_mm``), L1/L2 =
    400/200 mm, 300 placements in [-350, 350] x [-350, 350] x [700, 1000] mm;
    camera 1 at Euler angles (28.65, 28.65, 28.65) deg and T = [-700, 100, 200]
    mm, camera 2 (when n_cameras = 3) at (57.3, 57.3, 57.3) deg and
    T = [-1200, -200, 700] mm.
    """
    poses = [
        Pose.identity(),
        _euler_pose((28.65, 28.65, 28.65), (-700.0, 100.0, 200.0)),
        _euler_pose((57.3, 57.3, 57.3), (-1200.0, -200.0, 700.0)),
        _euler_pose((-28.65, -28.65, 28.65), (700.0, -100.0, 200.0)),  # (not the paper's: a fourth for paper4)
    ]
    cameras = []
    for i in range(n_cameras):
        spec = CameraSpec(f"cam{i}", (640, 480), (5.6, 5.6), nominal_focal_mm, 92.5)
        model = CameraModel(
            equisolid_taylor(true_focal_mm), spec.m, np.asarray(principal_point, dtype=float), spec.image_size
        )
        cameras.append(TrueCamera(spec, model, poses[i], np.radians(92.5)))
    volume = np.array([[-350.0, -350.0, 700.0], [350.0, 350.0, 1000.0]])
    return Scenario("paper", WandSpec.from_lengths(400.0, 200.0), tuple(cameras), volume, n_placements)


def _barrel_perspective(theta: FloatArray) -> FloatArray:
    """tan(theta) with mild barrel distortion, r/f of a typical 4 mm C-mount lens."""
    t = np.tan(theta)
    return t * (1.0 - 0.06 * t * t)


#: OpenCV distortion (k1, k2, p1, p2, k3) of the conventional cameras' lenses as plumb_bob describes them
#: (``pinhole=True``): the barrel of :func:`_barrel_perspective` and the tangential terms a board
#: calibration of a real low-cost 4 mm C-mount lens finds (0.5-1 px at the image edges), a little different
#: from camera to camera.
_PLUMB_BOB_LENSES = (
    (-0.060, 0.004, 2.0e-3, -1.5e-3, 0.0),
    (-0.066, 0.010, -1.8e-3, 2.2e-3, 0.0),
    (-0.055, 0.002, 1.6e-3, 1.9e-3, 0.0),
)


def _conventional_camera(
    name: str, pose: Pose, principal_point: tuple[float, float], pinhole: int | None = None
) -> TrueCamera:
    """The 4.2 mm camera; with ``pinhole`` its true lens is plumb_bob (``_PLUMB_BOB_LENSES[pinhole]``)."""
    spec = CameraSpec(name, (658, 492), (5.6, 5.6), 4.2, 43.385)
    if pinhole is not None:
        focal = 4.3 * spec.m[0]
        camera_matrix = np.array([[focal, 0.0, principal_point[0]], [0.0, focal, principal_point[1]], [0.0, 0.0, 1.0]])
        model = from_opencv_pinhole(camera_matrix, np.array(_PLUMB_BOB_LENSES[pinhole]), spec.m, spec.image_size)
        return TrueCamera(spec, model, pose, np.radians(48.0))
    k = fit_radial(_barrel_perspective, 4.3, np.radians(48.0))
    return TrueCamera(
        spec, CameraModel(k, spec.m, np.asarray(principal_point, dtype=float), spec.image_size), pose, np.radians(48.0)
    )


def _fisheye_camera(name: str, pose: Pose, principal_point: tuple[float, float]) -> TrueCamera:
    spec = CameraSpec(name, (658, 492), (5.6, 5.6), 1.8, 92.5)
    k = fit_radial("equidistant", 1.82, np.radians(95.0)) + np.array([0.0, 0.012, -0.002, 0.0, 0.0])
    return TrueCamera(
        spec, CameraModel(k, spec.m, np.asarray(principal_point, dtype=float), spec.image_size), pose, np.radians(92.5)
    )


#: Pose of the second camera in the paper's real two-camera experiments (Table 1).
_REAL_PAIR_POSE = Pose.from_rotvec(np.array([0.0729, 0.6276, 0.2053]), np.array([-1373.47, -180.03, 504.96]))
#: Wand-centre volume of the real-setup scenarios: fills the conventional cameras' common view.
_REAL_PAIR_VOLUME = np.array([[-1500.0, -1000.0, 800.0], [800.0, 1000.0, 3000.0]])


def conventional_pair_scenario(*, n_placements: int = 300, pinhole: bool = False) -> Scenario:
    """Two conventional cameras like the paper's real setup (658x492, 4.2 mm nominal, 86.77 deg); with
    ``pinhole`` their true lenses are plumb_bob ones (with tangential terms)."""
    cameras = (
        _conventional_camera("cam0", Pose.identity(), (335.0, 238.0), 0 if pinhole else None),
        _conventional_camera("cam1", _REAL_PAIR_POSE, (322.0, 251.0), 1 if pinhole else None),
    )
    volume = _REAL_PAIR_VOLUME
    return Scenario("conventional", WandSpec.from_lengths(400.0, 200.0), cameras, volume, n_placements)


def mixed_pair_scenario(*, n_placements: int = 300, pinhole: bool = False) -> Scenario:
    """A 1.8 mm 185-degree fisheye (cam0) with a 4.2 mm conventional camera (cam1; with ``pinhole`` its true
    lens is a plumb_bob one)."""
    cameras = (
        _fisheye_camera("cam0", Pose.identity(), (336.0, 241.0)),
        _conventional_camera("cam1", _REAL_PAIR_POSE, (322.0, 251.0), 1 if pinhole else None),
    )
    volume = _REAL_PAIR_VOLUME
    return Scenario("mixed", WandSpec.from_lengths(400.0, 200.0), cameras, volume, n_placements)


#: The real pair's conventional camera mirrored to the other side of the fisheye (x -> -x).
_MIRRORED_PAIR_POSE = Pose.from_rotvec(np.array([0.0729, -0.6276, -0.2053]), np.array([1373.47, -180.03, 504.96]))


def mixed_three_camera_scenario(*, n_placements: int = 300, pinhole: bool = False) -> Scenario:
    """The mixed pair with a second 4.2 mm camera mirrored to the fisheye's other side (a 3-camera mixed rig;
    with ``pinhole`` the conventional cameras' true lenses are plumb_bob ones)."""
    cameras = (
        _fisheye_camera("cam0", Pose.identity(), (336.0, 241.0)),
        _conventional_camera("cam1", _REAL_PAIR_POSE, (322.0, 251.0), 1 if pinhole else None),
        _conventional_camera("cam2", _MIRRORED_PAIR_POSE, (331.0, 244.0), 2 if pinhole else None),
    )
    volume = np.array([[-1500.0, -1000.0, 800.0], [1500.0, 1000.0, 3000.0]])
    return Scenario("mixed3", WandSpec.from_lengths(400.0, 200.0), cameras, volume, n_placements, min_views=2)


def conventional_four_scenario(*, n_placements: int = 300) -> Scenario:
    """Four 4.2 mm conventional cameras (the real pair's) on an arc 2.6 m around a 1.8 x 1.4 x 1.8 m volume, 36-37
    degrees apart and alternately 0.6 and 0.2 m above its centre, all looking at it: a small lab's motion-capture
    rig, where every camera sees most placements and each is placed by the others (a pair's two cameras only by
    each other and the wand)."""
    world_poses = []
    for i, azimuth in enumerate(np.radians([-55.0, -18.0, 18.0, 55.0])):
        height = -600.0 if i % 2 == 0 else -200.0  # (y is down)
        centre = np.array([2600.0 * np.sin(azimuth), height, -2600.0 * np.cos(azimuth)])
        world_poses.append(_look_at(centre, np.zeros(3), np.array([0.0, 1.0, 0.0])))
    principal_points = ((335.0, 238.0), (322.0, 251.0), (331.0, 244.0), (326.0, 240.0))
    cameras = tuple(
        _conventional_camera(f"cam{i}", pose, principal_points[i])
        for i, pose in enumerate(_relative_to_first(world_poses))
    )
    volume = _box_in(world_poses[0], (-900.0, -700.0, -900.0), (900.0, 700.0, 900.0))
    return Scenario("conventional4", WandSpec.from_lengths(400.0, 200.0), cameras, volume, n_placements)


def paper_three_camera_scenario(**kwargs: float | tuple[float, float]) -> Scenario:
    """The paper's three-fisheye simulation (camera 2 at Euler (57.3, 57.3, 57.3) deg, T = [-1200, -200, 700] mm)."""
    scenario = paper_fisheye_scenario(n_cameras=3, **kwargs)  # type: ignore[arg-type]
    return Scenario("paper3", scenario.wand, scenario.cameras, scenario.volume, scenario.n_placements)


def paper_four_camera_scenario(**kwargs: float | tuple[float, float]) -> Scenario:
    """The paper's three fisheyes and a fourth mirrored to camera 1's other side (Euler (-28.65, -28.65, 28.65) deg,
    T = [700, -100, 200] mm): four cameras that all see the wand's volume."""
    scenario = paper_fisheye_scenario(n_cameras=4, **kwargs)  # type: ignore[arg-type]
    return Scenario("paper4", scenario.wand, scenario.cameras, scenario.volume, scenario.n_placements)


def small_room_scenario() -> Scenario:
    """The paper's three fisheyes in a small room: the wand waved 0.4-1.4 m from them (0.75-1 m median), where
    its LEDs are far brighter than the sensor's full scale."""
    scenario = paper_three_camera_scenario()
    volume = np.array([[-100.0, -300.0, 500.0], [400.0, 200.0, 850.0]])
    return Scenario("small_room", scenario.wand, scenario.cameras, volume, scenario.n_placements)


def _look_at(centre: FloatArray, target: FloatArray, down: FloatArray) -> Pose:
    """Pose of a camera at ``centre`` looking at ``target`` with image y along ``down``."""
    z = (target - centre) / np.linalg.norm(target - centre)
    x = np.cross(down, z)
    x /= np.linalg.norm(x)
    rotation = np.stack([x, np.cross(z, x), z])
    return Pose(rotation, -rotation @ centre)


def _floor_in(first: Pose, point: FloatArray) -> FloatArray:
    """(3, 3) a floor through the world ``point`` (world y down) in the first camera's frame: point, up, x."""
    return np.stack(
        [first.apply(point), first.rotation @ np.array([0.0, -1.0, 0.0]), first.rotation @ np.array([1.0, 0.0, 0.0])]
    )


def _box_in(first: Pose, low: tuple[float, float, float], high: tuple[float, float, float]) -> FloatArray:
    """(2, 3) the least and greatest corner of the axis-aligned volume, in the first camera's frame, that holds the
    world box from ``low`` to ``high`` (mm)."""
    corners = np.array([[x, y, z] for x in (low[0], high[0]) for y in (low[1], high[1]) for z in (low[2], high[2])])
    in_first = first.apply(corners)
    return np.stack([in_first.min(axis=0), in_first.max(axis=0)])


def _relative_to_first(poses: list[Pose]) -> list[Pose]:
    """Re-express world poses so the first camera is the reference (X_cam = R X_ref + T)."""
    first = poses[0]
    inverse = first.inverse()
    return [pose.compose(inverse) for pose in poses]


def ring_scenario(*, n_placements: int = 600, radius_mm: float = 2500.0, cone_deg: float = 60.0) -> Scenario:
    """Six cameras on a ring around a 2 m cube, fisheye and conventional alternating.

    The LEDs shine into a cone of ``cone_deg`` around a random facing direction, so
    opposite cameras never see the same placement: the vision graph is a ring
    without a common field of view.
    """
    world_centres = [
        np.array([radius_mm * np.sin(a), 0.0, -radius_mm * np.cos(a)]) for a in np.radians(np.arange(6) * 60.0)
    ]
    world_poses = [_look_at(c, np.zeros(3), np.array([0.0, 1.0, 0.0])) for c in world_centres]
    poses = _relative_to_first(world_poses)
    cameras = []
    for i, pose in enumerate(poses):
        name = f"cam{i}"
        principal = (336.0 + 3 * i, 241.0 - 2 * i)
        cameras.append(
            _fisheye_camera(name, pose, principal) if i % 2 == 0 else _conventional_camera(name, pose, principal)
        )
    # The 2 m cube around the ring centre, in camera 0's frame (camera 0 looks at the centre along +z).
    centre = world_poses[0].apply(np.zeros(3))
    volume = np.stack([centre - 1000.0, centre + 1000.0])
    floor = _floor_in(world_poses[0], np.array([0.0, 1000.0, 0.0]))  # the cube's bottom, 1 m under the cameras
    wand = WandSpec.from_lengths(400.0, 200.0)
    return Scenario("ring6", wand, tuple(cameras), volume, n_placements, 2, cone_deg, floor=floor)


def mocap_scenario(*, n_cameras: int = 16, n_placements: int = 10_000, cone_deg: float = 75.0) -> Scenario:
    """A motion-capture rig: 1280x1024 cameras with 6 mm lenses on two rings around a 4 x 4 x 2 m volume."""
    world_poses = []
    for i in range(n_cameras):
        angle = 2 * np.pi * i / n_cameras
        height = -2600.0 if i % 2 == 0 else -1800.0  # y is down: cameras 1.8-2.6 m above the floor centre
        centre = np.array([5000.0 * np.sin(angle), height, -5000.0 * np.cos(angle)])
        world_poses.append(_look_at(centre, np.array([0.0, -600.0, 0.0]), np.array([0.0, 1.0, 0.0])))
    poses = _relative_to_first(world_poses)
    cameras = []
    for i, pose in enumerate(poses):
        spec = CameraSpec(f"cam{i:02d}", (1280, 1024), (4.8, 4.8), 6.0, 35.0)
        k = fit_radial(_barrel_perspective, 6.1 + 0.02 * (i % 5), np.radians(38.0))
        principal = np.array([640.0 + 4 * ((i * 7) % 5) - 8, 512.0 + 3 * ((i * 3) % 5) - 6])
        cameras.append(TrueCamera(spec, CameraModel(k, spec.m, principal, spec.image_size), pose, np.radians(38.0)))
    first = world_poses[0]
    volume = _box_in(first, (-2000.0, -2000.0, -2000.0), (2000.0, 0.0, 2000.0))
    floor = _floor_in(first, np.zeros(3))
    wand = WandSpec.from_lengths(400.0, 200.0)
    return Scenario("mocap16", wand, tuple(cameras), volume, n_placements, 2, cone_deg, floor=floor)


#: The stage scenario's zones: one ring of cameras every ZONE_MM along x.
ZONE_MM = 5000.0


def stage_scenario(*, n_rings: int = 4, per_ring: int = 16, n_placements: int = 50_000) -> Scenario:
    """A large motion-capture stage: ``n_rings`` rings of cameras side by side, each around its own 5 x 5 m
    zone of the floor (default 64 cameras over a 20 x 5 m stage), the wand waved up to 2 m high.

    Each ring's cameras hang 3 m from their zone's centre, alternately 4.0 m and 3.4 m high, looking
    down at it; three 6 mm lenses to one 3.5 mm wide lens, on 1280x1024 sensors. The LEDs shine into
    a 75 degree cone. A ring's cameras share most views among themselves, fewer with the neighbour
    rings' and few with rings further away (on 3,000 placements, 1,162 of the 2,016 camera pairs
    share 10 or more; ring 0 shares 35 times fewer view pairs with ring 3 than with itself).
    """
    world_poses, lenses = [], []
    for ring in range(n_rings):
        zone = np.array([ZONE_MM * (ring - (n_rings - 1) / 2), 0.0, 0.0])  # on the floor (y is down)
        for i in range(per_ring):
            angle = 2 * np.pi * (i + 0.5 * ring) / per_ring
            height = -4000.0 if i % 2 == 0 else -3400.0  # on a truss, looking down at the zone's floor
            centre = zone + np.array([3000.0 * np.sin(angle), height, -3000.0 * np.cos(angle)])
            world_poses.append(_look_at(centre, zone, np.array([0.0, 1.0, 0.0])))
            lenses.append(3.5 if i % 4 == 3 else 6.0)
    poses = _relative_to_first(world_poses)
    cameras = []
    for i, (pose, focal) in enumerate(zip(poses, lenses, strict=True)):
        view_deg = 50.0 if focal < 5 else 35.0
        spec = CameraSpec(f"cam{i:02d}", (1280, 1024), (4.8, 4.8), focal, view_deg)
        k = fit_radial(_barrel_perspective, focal * (1.0 + 0.004 * (i % 5)), np.radians(view_deg + 3.0))
        principal = np.array([640.0 + 4 * ((i * 7) % 5) - 8, 512.0 + 3 * ((i * 3) % 5) - 6])
        model = CameraModel(k, spec.m, principal, spec.image_size)
        cameras.append(TrueCamera(spec, model, pose, np.radians(view_deg + 3.0)))
    half_x = ZONE_MM / 2 * n_rings
    volume = _box_in(world_poses[0], (-half_x, -2000.0, -2500.0), (half_x, 0.0, 2500.0))
    name = f"stage{n_rings * per_ring}"
    return Scenario(name, WandSpec.from_lengths(400.0, 200.0), tuple(cameras), volume, n_placements, 2, 75.0)


#: The sparse take's lenses: OpenCV (k1, k2, p1, p2, k3) of each camera's board calibration.
_SPARSE_LENSES = (
    (-0.15, 0.11, 3e-4, -2e-4, 0.0),
    (-0.13, 0.08, -4e-4, 1e-4, 0.0),
    (-0.17, 0.14, 2e-4, 5e-4, 0.0),
    (-0.14, 0.09, -1e-4, -3e-4, 0.0),
)


def sparse_scenario(*, n_placements: int = 100) -> Scenario:
    """A short digitised take of a two-LED wand (289.6 mm) by four 2560x1600 cameras with 16 mm lenses
    (10 um pixels) and plumb_bob distortion, as a lab records one for easyWand.

    The cameras stand on a 100-degree arc 2.4 m from a 1.2 x 0.9 x 0.9 m volume, looking at it from 1.2
    m above; of each placement a camera recorded its view with probability ``view_rates`` (occlusion and
    digitising), and each marker of a recorded view is missing with probability 0.15: about 30 of 100
    frames show both markers to two or more cameras, pairs share 2-15 such views (seed to seed), and
    many views show one marker only.
    """
    target = np.array([0.0, 0.0, 0.0])
    world_poses, cameras = [], []
    for angle in np.radians([-50.0, -17.0, 17.0, 50.0]):
        centre = np.array([2400.0 * np.sin(angle), -1200.0, -2400.0 * np.cos(angle)])
        world_poses.append(_look_at(centre, target, np.array([0.0, 1.0, 0.0])))
    poses = _relative_to_first(world_poses)
    for i, (pose, lens) in enumerate(zip(poses, _SPARSE_LENSES, strict=True)):
        spec = CameraSpec(f"cam{i}", (2560, 1600), (10.0, 10.0), 16.0, 45.0)
        focal = (16.0 + 0.15 * (i - 1.5)) * spec.m[0]
        centre_px = (1279.5 + 9.0 * (i - 1.5), 799.5 - 6.0 * (i - 1.5))
        camera_matrix = np.array([[focal, 0.0, centre_px[0]], [0.0, focal, centre_px[1]], [0.0, 0.0, 1.0]])
        model = from_opencv_pinhole(camera_matrix, np.array(lens), spec.m, spec.image_size, PLUMB_BOB)
        cameras.append(TrueCamera(spec, model, pose, np.radians(47.0)))
    volume = _box_in(world_poses[0], (-600.0, -450.0, -450.0), (600.0, 450.0, 450.0))
    return Scenario(
        "sparse4",
        WandSpec((0.0, 289.6)),
        tuple(cameras),
        volume,
        n_placements,
        min_views=1,
        view_rates=(0.45, 0.4, 0.36, 0.3),
        marker_loss=0.15,
    )


def narrow_scenario(
    *, n_placements: int = 600, true_focal_mm: float = 250.0, nominal_focal_mm: float = 100.0
) -> Scenario:
    """Four long-lens cameras about 3 degrees across (1280x800, 10 um pixels, 250 mm lenses: fx 25,000 px), as
    particle-tracking rigs have, 1.5 m from a 50 x 30 x 50 mm volume on a 60-degree arc, with a two-ball wand
    of 20 mm; the rig description's nominal focal (``nominal_focal_mm``, default 100 mm) 2.5x below the truth.

    The lenses are distortion-free pinholes with principal points 10-25 px off the image centre: at 3 degrees
    the views determine the principal points only weakly (a shift trades with the camera's rotation).
    """
    target = np.zeros(3)
    world_poses, cameras = [], []
    for azimuth, elevation in ((-30.0, 12.0), (-10.0, -8.0), (10.0, 10.0), (30.0, -12.0)):
        a, e = np.radians(azimuth), np.radians(elevation)
        centre = 1500.0 * np.array([np.sin(a) * np.cos(e), -np.sin(e), -np.cos(a) * np.cos(e)])
        world_poses.append(_look_at(centre, target, np.array([0.0, 1.0, 0.0])))
    poses = _relative_to_first(world_poses)
    offsets = ((18.0, -12.0), (-22.0, 9.0), (11.0, 20.0), (-15.0, -16.0))
    for i, pose in enumerate(poses):
        view_deg = float(np.degrees(np.arctan(np.hypot(6.4, 4.0) / nominal_focal_mm)))
        spec = CameraSpec(
            f"cam{i}", (1280, 800), (10.0, 10.0), nominal_focal_mm, round(view_deg, 2), lens="conventional"
        )
        focal_mm = true_focal_mm * (1.0 + 0.004 * (i - 1.5))
        focal = focal_mm * spec.m[0]
        camera_matrix = np.array([[focal, 0.0, 639.5 + offsets[i][0]], [0.0, focal, 399.5 + offsets[i][1]], [0, 0, 1]])
        model = from_opencv_pinhole(camera_matrix, np.zeros(5), spec.m, spec.image_size, PLUMB_BOB)
        cameras.append(TrueCamera(spec, model, pose, np.radians(2.0)))
    volume = _box_in(world_poses[0], (-25.0, -15.0, -25.0), (25.0, 15.0, 25.0))
    return Scenario("narrow4", WandSpec((0.0, 20.0)), tuple(cameras), volume, n_placements)


#: The action cameras' lenses as their user's camera profile gives them: OpenCV (k1, k2, p1, p2, k3).
_ACTION_LENSES = ((-0.24, 0.07, 4e-4, -3e-4, -0.008), (-0.23, 0.06, -2e-4, 5e-4, -0.006))


def action_pair_scenario(*, n_placements: int = 322) -> Scenario:
    """Two action cameras (2704x1520, 1.55 um pixels, fx about 2,320 px, plumb_bob) filming a 300 mm
    two-marker wand far away, as field recordings of animal flight have it: 6-13 m from the first camera
    (the wand 20-130 px long there, shorter when it points at the camera), 17-23 m from the second (25-45
    px). Their intrinsics are known from the user's camera profile (give them: ``_given`` in the tests).
    """
    target = np.array([0.0, 0.0, 9000.0])
    world_poses = [
        _look_at(np.zeros(3), target, np.array([0.0, 1.0, 0.0])),
        _look_at(np.array([12000.0, -800.0, -5000.0]), target, np.array([0.0, 1.0, 0.0])),
    ]
    poses = _relative_to_first(world_poses)
    cameras = []
    for i, (pose, lens) in enumerate(zip(poses, _ACTION_LENSES, strict=True)):
        spec = CameraSpec(f"cam{i}", (2704, 1520), (1.55, 1.55), 3.6, 45.0, lens="conventional")
        focal = 2323.0 + 14.0 * i
        centre = (1351.5 + 11.0 - 20.0 * i, 759.5 - 7.0 + 12.0 * i)
        camera_matrix = np.array([[focal, 0.0, centre[0]], [0.0, focal, centre[1]], [0.0, 0.0, 1.0]])
        model = from_opencv_pinhole(camera_matrix, np.array(lens), spec.m, spec.image_size, PLUMB_BOB)
        cameras.append(TrueCamera(spec, model, pose, np.radians(42.0)))
    volume = np.array([[-2500.0, -1200.0, 5000.0], [2500.0, 1200.0, 11000.0]])
    return Scenario("action2", WandSpec((0.0, 300.0)), tuple(cameras), volume, n_placements)


SCENARIOS: dict[str, Callable[..., Scenario]] = {
    "paper": paper_fisheye_scenario,
    "paper3": paper_three_camera_scenario,
    "paper4": paper_four_camera_scenario,
    "small_room": small_room_scenario,
    "conventional": conventional_pair_scenario,
    "conventional4": conventional_four_scenario,
    "mixed": mixed_pair_scenario,
    "mixed3": mixed_three_camera_scenario,
    "ring6": ring_scenario,
    "mocap16": mocap_scenario,
    "stage64": stage_scenario,
    "sparse4": sparse_scenario,
    "narrow4": narrow_scenario,
    "action2": action_pair_scenario,
}


def lengths(vectors: FloatArray) -> FloatArray:
    """(...,) the lengths of (..., 3) vectors: the numbers numpy's norm over the last axis gives, without its
    reduction per vector (ten times as fast on a stage's 600,000 points)."""
    squares = vectors * vectors
    return np.asarray(np.sqrt(squares[..., 0] + squares[..., 1] + squares[..., 2]))


def visible(camera: TrueCamera, points: FloatArray) -> NDArray[np.bool_]:
    """(...,) True where reference-frame points reach the camera's sensor (only the points within its view angle are
    projected: a camera of a large stage sees a small part of it)."""
    in_cam = camera.pose.apply(points)
    theta = np.arctan2(np.hypot(in_cam[..., 0], in_cam[..., 1]), in_cam[..., 2])
    seen = (theta <= camera.true_max_view_angle) & (lengths(in_cam) > 1.0)
    uv = project(camera.model, in_cam[seen])
    width, height = camera.spec.image_size
    seen[seen] = (uv[:, 0] >= 0) & (uv[:, 0] <= width - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= height - 1)
    return seen


def _wand_points(scenario: Scenario, wand_a: FloatArray, direction: FloatArray) -> FloatArray:
    return wand_a[:, None, :] + scenario.wand.offsets[None, :, None] * direction[:, None, :]


def visibility(scenario: Scenario, wand_a: FloatArray, direction: FloatArray, facing: FloatArray) -> NDArray[np.bool_]:
    """(P, C, 3) which camera sees which LED: on the sensor and, with a cone, within the LEDs' beam."""
    points = _wand_points(scenario, wand_a, direction)
    seen = np.stack([visible(camera, points) for camera in scenario.cameras], axis=1)
    if scenario.led_cone_deg is not None:  # (looked at where the camera sees the LED)
        for c, camera in enumerate(scenario.cameras):
            mine = seen[:, c]
            to_camera = camera.pose.center - points[mine]  # (M, 3)
            along = np.einsum("mi,mi->m", to_camera, facing[np.nonzero(mine)[0]])  # (each LED's placement's facing)
            mine[mine] = along / lengths(to_camera) >= np.cos(np.radians(scenario.led_cone_deg))
    return seen


def sample_placements(
    scenario: Scenario, n: int, rng: np.random.Generator
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """n wand placements seen completely by enough cameras (``scenario.min_views``, default all).

    The wand centre is uniform in the scenario's volume, its direction and the
    LEDs' facing direction uniform on the sphere; other placements are redrawn.

    Returns:
        (A (n, 3), direction (n, 3), facing (n, 3)) in the reference frame.
    """
    needed = len(scenario.cameras) if scenario.min_views is None else scenario.min_views
    chunks: list[tuple[FloatArray, FloatArray, FloatArray]] = []
    count = 0
    for _ in range(1000):
        batch = max(4 * n, 100)
        centre = rng.uniform(scenario.volume[0], scenario.volume[1], size=(batch, 3))
        direction = rng.normal(size=(batch, 3))
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        facing = rng.normal(size=(batch, 3))
        facing /= np.linalg.norm(facing, axis=1, keepdims=True)
        a = centre - 0.5 * scenario.wand.L * direction
        ok = visibility(scenario, a, direction, facing).all(axis=2).sum(axis=1) >= needed
        chunks.append((a[ok], direction[ok], facing[ok]))
        count += int(ok.sum())
        if count >= n:
            break
    else:  # pragma: no cover - scenario definitions are checked by tests
        raise RuntimeError(f"scenario {scenario.name}: cameras rarely see the volume together")
    return tuple(np.concatenate([c[i] for c in chunks])[:n] for i in range(3))  # type: ignore[return-value]


def image_placements(
    scenario: Scenario,
    wand_a: FloatArray,
    direction: FloatArray,
    facing: FloatArray,
    noise_px: float,
    rng: np.random.Generator,
    *,
    first_frame: int = 0,
) -> SimulatedData:
    """Project placements into every camera and add Gaussian noise (NaN where not visible)."""
    points = _wand_points(scenario, wand_a, direction)
    seen = visibility(scenario, wand_a, direction, facing)
    uv = np.full((wand_a.shape[0], len(scenario.cameras), scenario.wand.n_points, 2), np.nan)
    for i, camera in enumerate(scenario.cameras):
        uv[:, i][seen[:, i]] = project(camera.model, camera.pose.apply(points[seen[:, i]]))
    uv = uv + rng.normal(scale=noise_px, size=uv.shape) if noise_px > 0 else uv
    frames = np.arange(first_frame, first_frame + wand_a.shape[0])
    names = tuple(c.spec.name for c in scenario.cameras)
    return SimulatedData(WandObservations(frames, names, uv), wand_a, direction, noise_px, facing)


def simulate(scenario: Scenario, noise_px: float, rng: np.random.Generator, n: int | None = None) -> SimulatedData:
    """Sample ``n`` (default: the scenario's count) placements and image them with noise (and, for a
    sparse take, drop the views and markers its ``view_rates`` and ``marker_loss`` lose)."""
    wand_a, direction, facing = sample_placements(scenario, scenario.n_placements if n is None else n, rng)
    data = image_placements(scenario, wand_a, direction, facing, noise_px, rng)
    return data if scenario.view_rates is None else sparse_views(scenario, data, rng)


def sparse_views(scenario: Scenario, data: SimulatedData, rng: np.random.Generator) -> SimulatedData:
    """The data with the views a sparse take did not record removed (see :attr:`Scenario.view_rates`)."""
    rates = np.asarray(scenario.view_rates, dtype=np.float64)
    uv = data.observations.uv.copy()
    recorded = rng.random(uv.shape[:2]) < rates[None, :]
    lost = rng.random(uv.shape[:3]) < scenario.marker_loss
    uv[~recorded] = np.nan
    uv[lost] = np.nan
    observations = data.observations.with_uv(uv)
    return SimulatedData(observations, data.wand_a, data.wand_direction, data.noise_px, data.facing)
