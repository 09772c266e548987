"""External-camera tracking: a body's markers relative to reference markers (report App. G)."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from visloc.markers import MarkerDetector
from visloc.pose import Camera
from visloc.pose.maps import GridMap, MarkerMap
from visloc.pose.relative import relative_pose, track_body
from visloc.synth import default_camera, render_markers
from visloc.types import Pose

SIZE = (640, 480)
K = default_camera(SIZE)
REFERENCE = GridMap(2, 2, 0.12, 0.04)  # ids 0-3 on the floor
BODY = GridMap(1, 2, 0.10, 0.02, first_id=10)  # two markers on the drone's top plate


def two_map_scene(T_ref_body: Pose, seed: int = 0):
    """A ceiling camera 2.2 m above the reference markers, looking down, seeing both maps."""
    R_ref_cam = np.diag([1.0, -1.0, -1.0])  # looking down at the floor
    cam_pos = np.array([0.5, -0.3, 2.2])
    T_cam_ref = Pose(R_ref_cam.T, -R_ref_cam.T @ cam_pos)
    placements = [(int(i), T_cam_ref.compose(REFERENCE.marker_pose(int(i))), 0.12) for i in REFERENCE.ids]
    T_cam_body = T_cam_ref.compose(T_ref_body)
    placements += [(int(i), T_cam_body.compose(BODY.marker_pose(int(i))), 0.10) for i in BODY.ids]
    return render_markers(K, SIZE, placements, "DICT_4X4_50", background="gravel", rng=seed, blur_sigma=0.5,
                          noise_sigma=1.0)


def write_track_inputs(root, yaw_step_deg: float, n: int) -> list[Pose]:
    """``root/frames/f<k>.png`` of a body moving 2 cm along x per frame and turning
    ``yaw_step_deg`` per frame from 10 deg, with ``body.yml``, ``ref.yml`` and ``cam.yml``
    (for ``visloc track``); returns the true poses."""
    import cv2

    from visloc.synth import write_camera_yml

    frames = root / "frames"
    frames.mkdir()
    truth = []
    for k in range(n):
        T = Pose(Rotation.from_euler("z", 10 + yaw_step_deg * k, degrees=True).as_matrix(),
                 np.array([0.5 + 0.02 * k, -0.3, 0.6]))
        cv2.imwrite(str(frames / f"f{k}.png"), two_map_scene(T, seed=k).image)
        truth.append(T)
    BODY.to_file(root / "body.yml")
    REFERENCE.to_file(root / "ref.yml")
    write_camera_yml(root / "cam.yml", default_camera(SIZE), SIZE)
    return truth

@pytest.mark.parametrize("yaw_deg, xyz", [(0.0, (0.6, -0.2, 0.5)), (35.0, (0.9, -0.5, 0.8)), (-120.0, (0.3, -0.6, 0.4))])
def test_body_pose_in_the_reference_frame(yaw_deg, xyz):
    T_ref_body = Pose(Rotation.from_euler("zyx", [yaw_deg, 3.0, -2.0], degrees=True).as_matrix(), np.array(xyz))
    scene = two_map_scene(T_ref_body)
    dets = MarkerDetector("DICT_4X4_50", response="linear").detect(scene.image)  # a linear render
    bp = track_body(dets, BODY, REFERENCE, Camera(K, size=SIZE))
    assert bp is not None
    assert np.linalg.norm(bp.position - T_ref_body.t) < 0.01  # 1 cm at 1.4-1.9 m from the camera
    assert abs(np.degrees(bp.yaw) - yaw_deg) < 0.5
    d = bp.to_dict()
    assert {"x", "y", "z", "yaw", "R", "rvec"} <= set(d)


def test_relative_pose_composition():
    T_cam_ref = Pose(Rotation.from_rotvec([0.1, -0.2, 0.3]).as_matrix(), np.array([0.1, 0.2, 2.0]))
    T_ref_body = Pose(Rotation.from_rotvec([0.0, 0.0, 0.7]).as_matrix(), np.array([0.4, -0.1, 0.3]))
    got = relative_pose(T_cam_ref.compose(T_ref_body), T_cam_ref)
    assert np.allclose(got.R, T_ref_body.R) and np.allclose(got.t, T_ref_body.t)


def test_missing_maps_and_shared_ids():
    cam = Camera(K, size=SIZE)
    assert track_body([], BODY, REFERENCE, cam) is None
    with pytest.raises(ValueError, match="share"):
        track_body([], GridMap(1, 2, 0.1, 0.0), REFERENCE, cam)
    assert isinstance(BODY, MarkerMap)


def test_relative_pose_wants_two_poses():
    pose = Pose(np.eye(3), np.array([0.0, 0.0, 1.0]))
    with pytest.raises(TypeError, match="T_cam_body must be a Pose, got ndarray"):
        relative_pose(np.eye(4), pose)
    with pytest.raises(TypeError, match="T_cam_ref must be a Pose, got ndarray"):
        relative_pose(pose, np.eye(4))
