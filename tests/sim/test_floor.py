"""Marker maps printed on the floor and seen from the simulated bottom camera."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from visloc.markers import MarkerDetector
from visloc.pose import Camera, GridMap, MarkerMap, estimate_camera_pose
from visloc.sim import BottomCamera, Vehicle
from visloc.synth.floor import FloorTexture
from visloc.synth.grid import LOOKING_DOWN, render_map_view
from visloc.types import Pose

GRID = GridMap(4, 4, 0.10, 0.05)


@pytest.fixture(scope="module")
def floor():
    return FloorTexture.from_map(GRID, "DICT_4X4_50")


def test_floor_view_localises_to_the_true_pose(floor):
    K = np.array([[320.0, 0, 159.5], [0, 320.0, 119.5], [0, 0, 1]])
    det, cam = MarkerDetector("DICT_4X4_50", response="linear"), Camera(K)  # linear renders
    rng = np.random.default_rng(2)
    centre = np.array([0.2875, -0.2875, 0.0])
    for _ in range(5):
        pos = centre + [*rng.uniform(-0.05, 0.05, 2), rng.uniform(0.6, 0.9)]
        R = Rotation.from_rotvec(rng.normal(0, 0.08, 3)).as_matrix() @ LOOKING_DOWN
        T = Pose(R.T, -R.T @ pos)
        img = floor.render(K, (320, 240), T, noise_sigma=2.0, rng=rng)
        fix = estimate_camera_pose(det.detect(img), GRID, cam)
        assert fix is not None and len(fix.used) >= 4
        assert np.linalg.norm(fix.position - pos) < 0.002
        exact = render_map_view(GRID, K, (320, 240), T, "DICT_4X4_50").render.image
        printed = (exact < 30) | (exact > 225)  # the exact renderer's marker print (grey elsewhere)
        assert np.mean(np.abs(img[printed].astype(float) - exact[printed])) < 10.0


def test_floor_errors(floor):
    K = np.array([[320.0, 0, 159.5], [0, 320.0, 119.5], [0, 0, 1]])
    below = Pose(LOOKING_DOWN.T, -LOOKING_DOWN.T @ np.array([0.3, -0.3, -0.5]))
    with pytest.raises(ValueError, match="above the floor"):
        floor.render(K, (320, 240), below)
    above = Pose(LOOKING_DOWN.T, -LOOKING_DOWN.T @ np.array([0.2875, -0.2875, 0.7]))
    # a float64 K is looked up by its values (checked once): the same view as K given as a list
    assert np.array_equal(floor.render(K, (320, 240), above), floor.render(K.tolist(), (320, 240), above))
    for bad in (np.array([[320.0, 0, 159.5], [0, -320.0, 119.5], [0, 0, 1]]), np.eye(2), K * np.nan):
        with pytest.raises(ValueError, match="K"):
            floor.render(bad, (320, 240), above)
    c, s = np.cos(0.5), np.sin(0.5)  # a marker on a ramp, not on the floor
    tilted = MarkerMap({0: np.array([[0, 0, 0], [0.1, 0, 0], [0.1, -0.1 * c, 0.1 * s], [0, -0.1 * c, 0.1 * s]])})
    with pytest.raises(ValueError, match="z = 0"):
        FloorTexture.from_map(tilted, "DICT_4X4_50")
    with pytest.raises(ValueError, match="not in"):
        FloorTexture.from_map(GridMap(8, 8, 0.1, 0.05), "DICT_4X4_50")


def test_bottom_camera_pose_round_trip():
    camera = BottomCamera(GRID, "DICT_4X4_50", noise_sigma=0.0)
    rng = np.random.default_rng(0)
    for _ in range(5):
        s = np.zeros(12)
        s[:3] = [*rng.uniform(-0.1, 0.1, 2), -1.0]
        s[6:9] = rng.uniform(-0.3, 0.3, 3)
        R = Vehicle(state=s).rotation()
        position, R_back = camera.body_from_map(camera.pose(s, R))
        np.testing.assert_allclose(position, s[:3], atol=1e-12)
        np.testing.assert_allclose(R_back, R, atol=1e-12)
    level = np.zeros(12)
    level[2] = -1.0
    T = camera.pose(level, np.eye(3))
    # looking down from 1 m above the map centre; the image's top is the body's front (north)
    np.testing.assert_allclose(T.R @ np.array([1.0, 0, 0]), [0, -1, 0], atol=1e-12)
    np.testing.assert_allclose(-T.R.T @ T.t, camera.centre + [0, 0, 1.0], atol=1e-12)


def test_the_warped_view_is_the_ray_traced_one():
    # the floor plane maps to the image by a homography: one warpPerspective of the texture
    # level gives the grey levels of the per-pixel rays, and views reaching beyond the
    # printed floor go back to the rays (their mirror tiling)
    from visloc.pose.maps import GridMap
    from visloc.pose.rotations import euler_to_matrix
    from visloc.sim.sensors import BottomCamera
    from visloc.synth.flight import _render
    from visloc.synth.floor import _warped

    cam = BottomCamera(GridMap(3, 3, 0.1, 0.05), "DICT_4X4_50", rng=np.random.default_rng(0))
    floor, rng, warped = cam.floor, np.random.default_rng(1), 0
    levels = tuple(level.astype(np.float32) for level in floor.levels)  # the geometry, without uint8 rounding
    for _ in range(8):
        state = np.zeros(12)
        state[:3] = [*rng.uniform(-0.05, 0.05, 2), -rng.uniform(0.3, 0.5)]
        pose = cam.pose(state, euler_to_matrix(rng.uniform(-0.1, 0.1, 3)))
        R, C = pose.R.T, -pose.R.T @ pose.t
        C[:2] -= floor.origin
        ray = _render(levels, cam.K, cam.size, R, C, floor.metres_per_texel, 2)
        fast = _warped(levels, cam.K, cam.size, R, C, floor.metres_per_texel, 2)
        if fast is not None:
            warped += 1
            assert np.abs(fast - ray).max() < 0.1
            as_stored = _warped(floor.levels, cam.K, cam.size, R, C, floor.metres_per_texel, 2)
            # rounded three times: the texels, the samples, their means (half a grey level each at most)
            assert as_stored.dtype == np.uint8 and np.abs(as_stored - ray).max() <= 1.5
    assert warped >= 4
    far = cam.pose(np.r_[5.0, 5.0, -0.4, np.zeros(9)], np.eye(3))  # over the floor's mirror tiling
    R, C = far.R.T, -far.R.T @ far.t
    C[:2] -= floor.origin
    assert _warped(floor.levels, cam.K, cam.size, R, C, floor.metres_per_texel, 2) is None


def test_bottom_camera_one_sample_per_pixel_puts_the_corners_where_they_are():
    """The sim's camera warps one bilinear sample per pixel of the texture level whose texels
    are about a pixel (the level is an area average already): noise-free, the detector's
    corners lie within a tenth of a pixel (RMS) of the true projections, against about 0.045
    px with 2 x 2 samples per pixel (measured: 0.066 and 0.045 px over 30 poses)."""
    from visloc.pose import markers_in_view
    from visloc.pose.rotations import euler_to_matrix

    cams = {s: BottomCamera(GRID, "DICT_4X4_50", noise_sigma=0.0, supersample=s) for s in (1, 2)}
    assert BottomCamera(GRID, "DICT_4X4_50").supersample == 1
    det, rng = MarkerDetector("DICT_4X4_50", response="linear"), np.random.default_rng(3)
    err: dict[int, list] = {1: [], 2: []}
    for _ in range(6):
        state = np.zeros(12)
        state[:3] = [*rng.uniform(-0.05, 0.05, 2), -rng.uniform(0.5, 1.2)]
        R = euler_to_matrix(rng.uniform(-0.1, 0.1, 3))
        for s, cam in cams.items():
            truth = markers_in_view(GRID, Camera(cam.K), cam.pose(state, R), size=cam.size)
            found = {d.id: d.corners for d in det.detect(cam.capture(state, R))}
            assert found.keys() == truth.keys()
            err[s] += [np.linalg.norm(found[i] - truth[i], axis=1) for i in truth]
    rms = {s: float(np.sqrt(np.mean(np.concatenate(e) ** 2))) for s, e in err.items()}
    assert rms[1] < 0.1 and rms[2] < 0.06 and rms[1] < 2.0 * rms[2], rms
    for bad, error in ((0, ValueError), (9, ValueError), (1.5, TypeError), (True, TypeError)):
        with pytest.raises(error, match="supersample"):
            BottomCamera(GRID, "DICT_4X4_50", supersample=bad)


def test_bottom_camera_noise_is_white_rounded_and_new_each_frame():
    """Each frame's noise is a window of the camera's noise field at a random offset: rounded
    Gaussian of ``noise_sigma`` within the frame, different from the last frame's, seeded."""
    state = np.zeros(12)
    state[2] = -0.8
    clean = BottomCamera(GRID, "DICT_4X4_50", noise_sigma=0.0).capture(state, np.eye(3))
    cam = BottomCamera(GRID, "DICT_4X4_50", noise_sigma=3.0, rng=np.random.default_rng(7))
    a, b = cam.capture(state, np.eye(3)), cam.capture(state, np.eye(3))
    again = BottomCamera(GRID, "DICT_4X4_50", noise_sigma=3.0, rng=np.random.default_rng(7)).capture(state, np.eye(3))
    np.testing.assert_array_equal(a, again)
    mid = (clean > 20) & (clean < 235)  # away from the clipping
    n = int(mid.sum())
    assert n > 5000
    se = 1.0 / np.sqrt(n)  # bounds at 4.5 standard errors
    for img in (a, b):
        d = img.astype(float)[mid] - clean[mid]
        assert abs(d.mean()) < 4.5 * 3.0 * se
        assert abs(d.std() - np.sqrt(9.0 + 1.0 / 12.0)) < 4.5 * 3.0 * se / np.sqrt(2.0)
        assert abs(np.corrcoef(d[:-1], d[1:])[0, 1]) < 4.5 * se  # white: neighbours uncorrelated
    da, db = a.astype(float)[mid] - clean[mid], b.astype(float)[mid] - clean[mid]
    assert abs(np.corrcoef(da, db)[0, 1]) < 4.5 * se  # the next frame's noise is not this frame's
