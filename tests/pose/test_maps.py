"""Marker maps and the camera pose from all visible markers of a map."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from visloc.markers import MarkerDetector
from visloc.pose import Camera
from visloc.pose.map_pose import estimate_camera_pose, markers_in_view
from visloc.pose.maps import GridMap, MarkerMap
from visloc.synth.grid import random_map_view
from visloc.types import MarkerDetection, Pose

K = np.array([[320.067, 0, 159.5], [0, 320.067, 119.5], [0, 0, 1]])
CAM = Camera(K, size=(320, 240))


def test_grid_layout_ids_and_marker_frames():
    g = GridMap(2, 3, 0.1, 0.05, first_id=10)
    assert list(g.ids) == [10, 11, 12, 13, 14, 15]
    assert np.allclose(g.corners_of(10), [[0, 0, 0], [0.1, 0, 0], [0.1, -0.1, 0], [0, -0.1, 0]])
    assert np.allclose(g.corners_of(15)[0], [0.3, -0.15, 0])  # row 1, column 2
    T = g.marker_pose(10)  # the marker's own frame: centre, x right, y up, z out of the face
    assert np.allclose(T.t, [0.05, -0.05, 0]) and np.allclose(T.R, np.eye(3))
    L = 0.1
    own = np.array([[-L / 2, L / 2, 0], [L / 2, L / 2, 0], [L / 2, -L / 2, 0], [-L / 2, -L / 2, 0]])
    assert np.allclose(T.apply(own), g.corners_of(10))


def test_yaml_round_trip(tmp_path):
    g = GridMap(3, 2, 0.08, 0.02, first_id=5)
    g.to_file(tmp_path / "map.yml")
    h = MarkerMap.from_file(tmp_path / "map.yml")
    assert list(h.ids) == list(g.ids)
    assert all(np.allclose(h.corners_of(i), g.corners_of(i)) for i in g.ids)


def test_bad_maps_are_rejected(tmp_path):
    square = np.array([[0, 0, 0], [1, 0, 0], [1, -1, 0], [0, -1, 0.0]])
    with pytest.raises(ValueError, match="duplicate"):
        MarkerMap.from_list([(1, square), (1, square + 2)])
    bent = square.copy()
    bent[2, 2] = 0.3
    with pytest.raises(ValueError, match="marker 4"):
        MarkerMap({4: bent})
    with pytest.raises(ValueError, match="square"):
        MarkerMap({4: square * [2, 1, 1]})
    with pytest.raises(ValueError, match="does not exist"):
        MarkerMap.from_file(tmp_path / "none.yml")
    (tmp_path / "bad.yml").write_text("%YAML:1.0\nmarkers:\n   - { id: 1, corners: [ 1, 2, 3 ] }\n")
    with pytest.raises(ValueError, match="12"):
        MarkerMap.from_file(tmp_path / "bad.yml")
    with pytest.raises(ValueError, match="rows"):
        GridMap(0, 2, 0.1, 0.0)


def test_pose_from_exact_corners_recovers_the_camera():
    g = GridMap(4, 4, 0.1, 0.05)
    R_map_cam = Rotation.from_euler("xyz", [175, 8, 30], degrees=True).as_matrix()
    pos = np.array([0.3, -0.25, 1.1])
    R, t = R_map_cam.T, -R_map_cam.T @ pos
    dets = []
    for i in g.ids:
        q = g.corners_of(i) @ R.T + t
        dets.append(MarkerDetection(int(i), (q[:, :2] / q[:, 2:]) @ K[:2, :2].T + K[:2, 2]))
    dets.append(MarkerDetection(99, dets[0].corners + 5.0))  # not in the map
    mp = estimate_camera_pose(dets, g, CAM)
    assert np.allclose(mp.position, pos, atol=1e-6)
    assert np.allclose(mp.R_map_cam, R_map_cam, atol=1e-7)
    assert mp.unknown == [99] and mp.rejected == [] and len(mp.used) == 16
    assert mp.pose.reprojection_rms < 1e-4
    assert np.allclose(mp.state[:3], pos, atol=1e-6)


def test_a_marker_inconsistent_with_the_rest_is_rejected():
    g = GridMap(3, 3, 0.1, 0.05)
    R_map_cam = np.diag([1.0, -1.0, -1.0])
    pos = np.array([0.2, -0.2, 0.9])
    R, t = R_map_cam.T, -R_map_cam.T @ pos
    dets = []
    for i in g.ids:
        q = g.corners_of(i) @ R.T + t
        c = (q[:, :2] / q[:, 2:]) @ K[:2, :2].T + K[:2, 2]
        dets.append(MarkerDetection(int(i), c + (12.0 if i == 4 else 0.0)))  # marker 4 moved
    mp = estimate_camera_pose(dets, g, CAM)
    assert mp.rejected == [4] and 4 not in mp.used
    assert np.allclose(mp.position, pos, atol=1e-6)
    assert mp.residuals[4] > 10


def test_rendered_grid_views_give_submillimetre_positions():
    g = GridMap(6, 6, 0.1, 0.05)
    det = MarkerDetector("DICT_4X4_50", response="linear")  # linear renders
    rng = np.random.default_rng(5)
    errs = []
    for _ in range(6):
        v = random_map_view(rng, g, K, (320, 240), "DICT_4X4_50", background="gravel", blur_sigma=0.5, noise_sigma=1.5)
        mp = estimate_camera_pose(det.detect(v.render.image), g, CAM)
        errs.append(np.linalg.norm(mp.position - v.position))
        cov = mp.pose.covariance
        assert cov is not None and np.allclose(cov, cov.T)
    assert np.median(errs) < 0.001, errs


def _exact_view(g, R_map_cam, pos, moved=None):
    R, t = R_map_cam.T, -R_map_cam.T @ pos
    dets = []
    for i in g.ids:
        q = g.corners_of(i) @ R.T + t
        c = (q[:, :2] / q[:, 2:]) @ K[:2, :2].T + K[:2, 2]
        dets.append(MarkerDetection(int(i), c + (12.0 if i == moved else 0.0)))
    return dets


def test_a_start_near_the_answer_gives_the_same_pose_and_a_far_one_is_dropped():
    # a video's previous pose as the start: the same fit; a start that leaves a marker beyond
    # max_residual (here turned half round) is dropped and the fit made from the markers' own poses
    g = GridMap(4, 4, 0.1, 0.05)
    R_map_cam = Rotation.from_euler("xyz", [178, 5, 20], degrees=True).as_matrix()
    pos = np.array([0.25, -0.2, 1.0])
    dets = _exact_view(g, R_map_cam, pos)
    cold = estimate_camera_pose(dets, g, CAM)
    near = Pose(Rotation.from_euler("z", 2, degrees=True).as_matrix() @ cold.pose.R, cold.pose.t + 0.01)
    far = Pose(Rotation.from_euler("z", 180, degrees=True).as_matrix() @ cold.pose.R, cold.pose.t)
    for start in (near, far, cold.pose):
        warm = estimate_camera_pose(dets, g, CAM, start=start)
        assert np.allclose(warm.position, pos, atol=1e-6) and np.allclose(warm.R_map_cam, R_map_cam, atol=1e-7)
        assert warm.rejected == [] and len(warm.used) == 16
    moved = estimate_camera_pose(_exact_view(g, R_map_cam, pos, moved=5), g, CAM, start=cold.pose)
    assert moved.rejected == [5] and np.allclose(moved.position, pos, atol=1e-6)  # the full fit decides
    with pytest.raises(TypeError, match="start"):
        estimate_camera_pose(dets, g, CAM, start=cold)


def test_nothing_seen_and_bad_arguments():
    g = GridMap(2, 2, 0.1, 0.05)
    assert estimate_camera_pose([], g, CAM) is None
    assert estimate_camera_pose([MarkerDetection(77, np.zeros((4, 2)))], g, CAM) is None
    with pytest.raises(TypeError, match="marker_map"):
        estimate_camera_pose([], {}, CAM)
    with pytest.raises(TypeError, match="camera"):
        estimate_camera_pose([], g, K)


def test_position_covariance_matches_monte_carlo():
    """The propagated camera-centre covariance predicts the spread of positions from noisy corners."""
    g = GridMap(3, 3, 0.1, 0.05)
    R_map_cam = Rotation.from_euler("xyz", [172, 5, 20], degrees=True).as_matrix()
    pos = np.array([0.2, -0.2, 0.9])
    R, t = R_map_cam.T, -R_map_cam.T @ pos
    rng = np.random.default_rng(1)
    exact = {}
    for i in g.ids:
        q = g.corners_of(i) @ R.T + t
        exact[int(i)] = (q[:, :2] / q[:, 2:]) @ K[:2, :2].T + K[:2, 2]
    positions, covs = [], []
    for _ in range(150):
        dets = [MarkerDetection(i, c + rng.normal(0, 0.3, c.shape)) for i, c in exact.items()]
        mp = estimate_camera_pose(dets, g, CAM, pixel_sigma=0.3)
        positions.append(mp.position)
        covs.append(mp.position_covariance)
    emp = np.std(positions, axis=0)
    pred = np.sqrt(np.diag(np.mean(covs, axis=0)))
    assert np.all(emp / pred > 0.7) and np.all(emp / pred < 1.4), (emp, pred)



def test_position_covariance_is_the_jacobian_of_the_camera_centre_even_at_pitch_90():
    """``c = -R^T t`` through the pose's six parameters: the analytic columns against central
    differences, and at the Z-Y-X singularity (pitch exactly 90 deg, roll then taken as 0, as
    ``matrix_to_euler`` takes it) a finite answer."""
    from visloc.pose.map_pose import MapPose
    from visloc.pose.rotations import euler_to_matrix

    def centre(p):
        return -euler_to_matrix(p[3:]).T @ p[:3]

    rng = np.random.default_rng(3)
    cov = np.diag([1e-6, 2e-6, 3e-6, 1e-4, 2e-4, 3e-4])
    c, s = np.cos(0.5), np.sin(0.5)
    pitch_90 = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ np.array([[0.0, 0, 1], [0, 1, 0], [-1, 0, 0]])
    for angles, R in (([0.3, -0.4, 1.2], None), ([2.9, 0.2, -0.7], None), ([0.0, np.pi / 2, 0.5], pitch_90)):
        p = np.r_[rng.normal(0.0, 1.0, 3), angles]
        R = euler_to_matrix(p[3:]) if R is None else R
        J = np.array([(centre(p + h) - centre(p - h)) / 2e-6 for h in 1e-6 * np.eye(6)]).T
        got = MapPose(Pose(R, p[:3], 0.1, cov), [], [], [], {}).position_covariance
        np.testing.assert_allclose(got, J @ cov @ J.T, rtol=1e-6, atol=1e-15)

@pytest.mark.parametrize("kw", [{"max_residual": float("nan")}, {"max_residual": 0.0}, {"pixel_sigma": -1.0},
                                {"max_iter": 2.5}, {"n_starts": 0}, {"max_iter": True}])
def test_options_it_cannot_use_are_refused_not_half_used(kw):
    g = GridMap(2, 2, 0.1, 0.05)
    with pytest.raises(ValueError, match="must be a"):
        estimate_camera_pose([MarkerDetection(0, np.array([[0, 0], [10, 0], [10, 10], [0, 10.0]]))], g, CAM, **kw)


def test_a_map_records_its_dictionary_and_an_empty_map_is_refused(tmp_path):
    g = GridMap(2, 3, 0.1, 0.05, dictionary="DICT_4X4_100")
    g.to_file(tmp_path / "m.yml")
    back = MarkerMap.from_file(tmp_path / "m.yml")
    assert back.dictionary == "DICT_4X4_100" and len(back) == 6
    GridMap(1, 1, 0.1, 0.0).to_file(tmp_path / "plain.yml")
    assert MarkerMap.from_file(tmp_path / "plain.yml").dictionary is None
    (tmp_path / "empty.yml").write_text("%YAML:1.0\nmarkers: []\n")
    with pytest.raises(ValueError, match="no markers"):
        MarkerMap.from_file(tmp_path / "empty.yml")


def test_markers_in_view_are_the_whole_ones_projected():
    g = GridMap(6, 6, 0.1, 0.05)
    R_map_cam = Rotation.from_euler("xyz", [178, 4, 20], degrees=True).as_matrix()
    pos = np.array([0.45, -0.4, 0.55])  # low: part of the grid is out of view
    pose = Pose(R_map_cam.T, -R_map_cam.T @ pos)
    seen = markers_in_view(g, CAM, pose)
    whole = {}
    for i in g.ids:
        q = g.corners_of(i) @ pose.R.T + pose.t
        px = (q[:, :2] / q[:, 2:]) @ K[:2, :2].T + K[:2, 2]
        if (px >= 0).all() and (px <= [319, 239]).all():
            whole[int(i)] = px
    assert 0 < len(whole) < len(g.ids)  # some whole, some cut by the frame's edge
    assert sorted(seen) == sorted(whole)
    assert all(np.allclose(seen[i], whole[i], atol=1e-9) for i in whole)
    edge = {i: min(q.min(), (np.array([319, 239]) - q).min()) for i, q in whole.items()}  # px from the edge
    margin = 0.5 * (min(edge.values()) + max(edge.values()))
    assert sorted(markers_in_view(g, CAM, pose, margin=margin)) == sorted(i for i, e in edge.items() if e >= margin)
    up = R_map_cam @ np.diag([1.0, -1.0, -1.0])  # the same camera looking up, away from the floor
    behind = Pose(up.T, -up.T @ pos)
    assert markers_in_view(g, CAM, behind) == {}


def test_markers_in_view_through_a_lens_and_bad_arguments():
    g = GridMap(4, 4, 0.1, 0.05)
    lens = Camera(K, dist=[-0.25, 0.08, 0.0, 0.0, 0.0], size=(320, 240))
    R_map_cam = Rotation.from_euler("xyz", [180, 0, 10], degrees=True).as_matrix()
    pose = Pose(R_map_cam.T, -R_map_cam.T @ np.array([0.275, -0.275, 0.9]))
    seen = markers_in_view(g, lens, pose)
    assert len(seen) == 16
    for i, q in seen.items():
        assert np.allclose(q, lens.project_object(g.corners_of(i), pose), atol=1e-9)
    with pytest.raises(TypeError, match="pose"):
        markers_in_view(g, lens, np.eye(4))
    with pytest.raises(ValueError, match="size"):
        markers_in_view(g, Camera(K), pose)
    with pytest.raises(ValueError, match="margin"):
        markers_in_view(g, lens, pose, margin=-1.0)


def test_a_map_keeps_its_own_read_only_corners_and_whole_ids(tmp_path):
    square = np.array([[0, 0, 0], [1, 0, 0], [1, -1, 0], [0, -1, 0.0]])
    m = MarkerMap({3: square, 4.0: square + [2, 0, 0]})
    square[0, 0] = 9.0  # the caller's array changes; the map's does not
    assert m.corners_of(3)[0, 0] == 0.0 and list(m.ids) == [3, 4]
    with pytest.raises(ValueError, match="read-only"):
        m.corners_of(3)[0, 0] = 1.0
    with pytest.raises(ValueError, match="whole number"):
        MarkerMap({1.5: square})
    with pytest.raises(TypeError, match="whole number"):
        MarkerMap.from_list([("a", square)])
    (tmp_path / "frac.yml").write_text("%YAML:1.0\nmarkers:\n   - { id: 1.5, corners: [ 0, 0, 0, 1, 0, 0, 1, -1, 0, "
                                       "0, -1, 0 ] }\n")
    with pytest.raises(ValueError, match="entry 0.*whole number"):
        MarkerMap.from_file(tmp_path / "frac.yml")
    with pytest.raises(ValueError, match="empty marker map"):
        MarkerMap({}).to_file(tmp_path / "empty.yml")
    assert not (tmp_path / "empty.yml").exists()


def test_bad_corners_and_a_repeated_id_are_named_not_fitted():
    g = GridMap(2, 2, 0.1, 0.05)
    dets = _exact_view(g, np.diag([1.0, -1.0, -1.0]), np.array([0.1, -0.1, 0.8]))
    nan = [MarkerDetection(0, np.full((4, 2), np.nan)), *dets[1:]]
    with pytest.raises(ValueError, match=r"detections: marker 0's corners must be finite"):
        estimate_camera_pose(nan, g, CAM)
    short = [*dets[:1], MarkerDetection(1, dets[1].corners[:3]), *dets[2:]]
    with pytest.raises(ValueError, match=r"detections: marker 1's corners must be \(4, 2\), got \(3, 2\)"):
        estimate_camera_pose(short, g, CAM)
    with pytest.raises(ValueError, match=r"detections: marker 2's corners must be \(4, 2\), got \(8,\)"):
        estimate_camera_pose([*dets[:2], MarkerDetection(2, dets[2].corners.ravel()), dets[3]], g, CAM)
    twice = estimate_camera_pose([*dets, MarkerDetection(3, dets[3].corners + 1.0)], g, CAM)
    assert twice.used == [0, 1, 2] and twice.rejected == [3]  # which copy is marker 3 is unknown: neither is used
    # a marker not in the map is ignored and listed, whatever its corners
    mp = estimate_camera_pose([*dets, MarkerDetection(9, np.full((3, 2), np.nan))], g, CAM)
    assert mp.unknown == [9] and mp.used == [0, 1, 2, 3] and np.isfinite(mp.pose.reprojection_rms)


def test_markers_in_view_names_a_bad_size_or_pose_and_takes_numpy_margins():
    g = GridMap(4, 4, 0.1, 0.05)
    R_map_cam = Rotation.from_euler("xyz", [180, 0, 10], degrees=True).as_matrix()
    pose = Pose(R_map_cam.T, -R_map_cam.T @ np.array([0.275, -0.275, 0.9]))
    seen = markers_in_view(g, CAM, pose, margin=1.0)
    assert len(seen) == 16
    for size in ((np.int64(320), 240.0), [320, np.int32(240)]):
        got = markers_in_view(g, CAM, pose, size=size, margin=np.float32(1))
        assert sorted(got) == sorted(seen) and all(np.array_equal(got[i], seen[i]) for i in seen)
    for size, kind, what in [((np.nan, 480), ValueError, "nan"), ((640,), ValueError, r"\(640,\)"),
                             ((640, 480, 3), ValueError, "480, 3"), ((640.5, 480), ValueError, "640.5"),
                             ((0, 480), ValueError, "0, 480"), ("ab", TypeError, "'ab'"),
                             ((640, None), TypeError, "None"), ((True, 480), TypeError, "True"),
                             (640, TypeError, "640")]:
        with pytest.raises(kind, match=rf"size .*{what}"):
            markers_in_view(g, CAM, pose, size=size)
    bad = Pose(pose.R, np.array([0.0, np.nan, 1.0]))
    with pytest.raises(ValueError, match="pose: .*finite"):
        markers_in_view(g, CAM, bad)
    with pytest.raises(ValueError, match="pose: .*finite"):
        markers_in_view(g, CAM, Pose(np.full((3, 3), np.inf), pose.t))
    for margin in (np.nan, True, "1"):
        with pytest.raises(ValueError, match="margin"):
            markers_in_view(g, CAM, pose, margin=margin)


def test_an_id_with_a_fraction_is_in_no_map():
    # int() used to truncate: corners_of(0.5) was marker 0, first_id=1.5 built ids 1, 2
    m = GridMap(2, 2, 0.1, 0.05)
    np.testing.assert_array_equal(m.corners_of(1.0), m.corners_of(1))
    for bad in (0.5, True, "1"):
        with pytest.raises(KeyError):
            m.corners_of(bad)
        with pytest.raises(KeyError):
            m.marker_pose(bad)
    with pytest.raises(ValueError, match="first_id"):
        GridMap(1, 2, 0.1, 0.0, first_id=1.5)
    assert GridMap(1, 2, 0.1, 0.0, first_id=2.0).ids.tolist() == [2, 3]
