"""visloc.pose.estimate_marker_pose: accuracy, flips, covariance, input checks."""

from __future__ import annotations

import types
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from visloc.pose import (
    Camera,
    estimate_marker_pose,
    is_flip,
    marker_object_points,
    pose_error,
    rotation_angle,
)
from visloc.pose.gauss_newton import reprojection_residuals
from visloc.types import Pose

CALIB = Path(__file__).resolve().parents[2] / "calib"
PINHOLE = Camera(
    np.array([[600.0, 0.0, 319.5], [0.0, 600.0, 239.5], [0.0, 0.0, 1.0]]), size=(640, 480)
)
TUTORIAL = Camera.from_file(CALIB / "opencv_tutorial_camera.yml")
L = 0.1
OBJ = marker_object_points(L)


def corners_of(camera: Camera, R: np.ndarray, t: np.ndarray, length: float = L) -> np.ndarray:
    return camera.project(marker_object_points(length) @ R.T + t)


@pytest.mark.parametrize("camera", [PINHOLE, TUTORIAL], ids=["pinhole", "distorted"])
def test_exact_corners_give_the_exact_pose(poses: types.SimpleNamespace, camera: Camera) -> None:
    rng = np.random.default_rng(1)
    for _ in range(100):
        R, t = poses.random_marker_pose(rng)
        pose = estimate_marker_pose(corners_of(camera, R, t), L, camera)
        rot, trans = pose_error(pose, R, t)
        assert rot < 1e-6 and trans < 1e-6
        assert pose.reprojection_rms < 1e-6
        assert not is_flip(pose, R)
        np.testing.assert_allclose(pose.R @ pose.R.T, np.eye(3), atol=1e-12)


@given(
    dist=st.floats(0.3, 3.0),
    tilt=st.floats(0.0, np.radians(60.0)),
    tilt_dir=st.floats(0.0, 2 * np.pi),
    yaw=st.floats(-np.pi, np.pi),
    ray_x=st.floats(-0.3, 0.3),
    ray_y=st.floats(-0.25, 0.25),
    length=st.sampled_from([0.05, 0.1, 0.2]),
)
@settings(max_examples=150, deadline=None)
def test_property_any_pose_in_front_is_recovered(
    poses: types.SimpleNamespace,
    dist: float,
    tilt: float,
    tilt_dir: float,
    yaw: float,
    ray_x: float,
    ray_y: float,
    length: float,
) -> None:
    ray = np.array([ray_x, ray_y, 1.0])
    R, t = poses.marker_pose(tilt, tilt_dir, yaw, dist * ray / np.linalg.norm(ray))
    corners = corners_of(TUTORIAL, R, t, length)
    # in the 640x480 image: outside it the lens model need not be invertible
    assume(np.all((corners > 0.0) & (corners < [639.0, 479.0])))
    pose = estimate_marker_pose(corners, length, TUTORIAL)
    rot, trans = pose_error(pose, R, t)
    assert rot < 1e-6 and trans < 1e-6


def test_agrees_with_opencv_ippe_square_on_noisy_corners(poses: types.SimpleNamespace) -> None:
    rng = np.random.default_rng(3)
    ours, theirs = [], []
    for _ in range(200):
        R, t = poses.random_marker_pose(rng, dist=(0.3, 1.5))
        corners = corners_of(TUTORIAL, R, t) + rng.normal(0.0, 0.5, (4, 2))
        pose = estimate_marker_pose(corners, L, TUTORIAL)
        ok, rvec, tvec = cv2.solvePnP(
            OBJ, corners, TUTORIAL.K, TUTORIAL.dist, flags=cv2.SOLVEPNP_IPPE_SQUARE
        )
        assert ok
        ref = Pose(cv2.Rodrigues(rvec)[0], tvec.ravel())
        if rotation_angle(pose.R.T @ ref.R) < 0.1:  # same solution: ours fits at least as well
            ref_px = TUTORIAL.undistort_points(TUTORIAL.project_object(OBJ, ref))
            obs = TUTORIAL.undistort_points(corners)
            ref_rms = np.sqrt(((ref_px - obs) ** 2).sum(axis=1).mean())
            assert pose.reprojection_rms <= ref_rms + 1e-9
        ours.append(pose_error(pose, R, t))
        theirs.append(pose_error(ref, R, t))
    ours_med = np.median(ours, axis=0)
    theirs_med = np.median(theirs, axis=0)
    assert np.all(ours_med <= 1.2 * theirs_med)
    assert np.all(theirs_med <= 1.2 * ours_med)


def test_tilted_marker_has_a_worse_alternative(poses: types.SimpleNamespace) -> None:
    R, t = poses.marker_pose(np.radians(40.0), 0.3, 0.5, np.array([0.05, -0.02, 1.0]))
    pose = estimate_marker_pose(corners_of(PINHOLE, R, t), L, PINHOLE)
    assert pose.alternative is not None
    assert pose.alternative_rms == pose.alternative.reprojection_rms
    assert pose.alternative_rms > 0.05 > pose.reprojection_rms
    # the alternative is the "flip": a clearly different rotation
    assert rotation_angle(pose.R.T @ pose.alternative.R) > np.radians(20.0)
    assert pose.alternative.covariance is not None


def test_face_on_marker_has_no_distinct_alternative(poses: types.SimpleNamespace) -> None:
    R, t = poses.marker_pose(0.0, 0.0, 0.3, np.array([0.0, 0.0, 1.0]))
    pose = estimate_marker_pose(corners_of(PINHOLE, R, t), L, PINHOLE)
    assert pose.alternative is None and pose.alternative_rms is None
    assert max(pose_error(pose, R, t)) < 1e-9


def test_is_flip_spots_the_wrong_solution(poses: types.SimpleNamespace) -> None:
    R, t = poses.marker_pose(np.radians(40.0), 0.3, 0.5, np.array([0.05, -0.02, 1.0]))
    pose = estimate_marker_pose(corners_of(PINHOLE, R, t), L, PINHOLE)
    flipped = Pose(pose.alternative.R, pose.alternative.t, alternative=pose)
    assert not is_flip(pose, R)
    assert is_flip(flipped, R)


def test_covariance_matches_monte_carlo(poses: types.SimpleNamespace) -> None:
    R, t = poses.marker_pose(np.radians(35.0), 0.4, 0.6, np.array([0.05, -0.03, 0.8]))
    length = 0.15
    exact = corners_of(PINHOLE, R, t, length)
    sigma = 0.3
    ref = estimate_marker_pose(exact, length, PINHOLE, pixel_sigma=sigma)
    cov = ref.covariance
    assert cov is not None and cov.shape == (6, 6)
    np.testing.assert_allclose(cov, cov.T)
    assert np.linalg.eigvalsh(cov).min() > 0.0
    rng = np.random.default_rng(42)
    deltas = []
    for _ in range(200):
        pose = estimate_marker_pose(exact + rng.normal(0.0, sigma, (4, 2)), length, PINHOLE)
        assert not is_flip(pose, R)
        d = pose.params - ref.params
        d[3:] = (d[3:] + np.pi) % (2 * np.pi) - np.pi
        deltas.append(d)
    empirical = np.std(deltas, axis=0)
    predicted = np.sqrt(np.diag(cov))
    for k in (2, 5):  # tz and psi
        assert predicted[k] / 1.5 < empirical[k] < predicted[k] * 1.5


def test_covariance_is_sigma_squared_inverse_normal_matrix(poses: types.SimpleNamespace) -> None:
    R, t = poses.marker_pose(np.radians(25.0), 1.0, 2.0, np.array([-0.1, 0.05, 1.2]))
    pose = estimate_marker_pose(corners_of(PINHOLE, R, t), L, PINHOLE, pixel_sigma=0.5)
    # numerical Jacobian of the pixel residuals at Pose.params
    X = OBJ.T.copy()
    xy = PINHOLE.normalize(corners_of(PINHOLE, R, t)).T.copy()
    f = np.array([[PINHOLE.fx], [PINHOLE.fy]])
    J = np.empty((8, 6))
    for k in range(6):
        d = np.zeros(6)
        d[k] = 1e-6
        hi = reprojection_residuals((pose.params + d)[None], X, xy, f)[0]
        lo = reprojection_residuals((pose.params - d)[None], X, xy, f)[0]
        J[:, k] = (hi - lo) / 2e-6
    np.testing.assert_allclose(pose.covariance, 0.25 * np.linalg.inv(J.T @ J), rtol=1e-4)


def test_default_sigma_comes_from_the_residuals(poses: types.SimpleNamespace) -> None:
    R, t = poses.marker_pose(np.radians(30.0), 0.2, 0.1, np.array([0.0, 0.0, 1.0]))
    exact = corners_of(PINHOLE, R, t)
    floor = estimate_marker_pose(exact, L, PINHOLE)
    given_ = estimate_marker_pose(exact, L, PINHOLE, pixel_sigma=0.05)
    np.testing.assert_allclose(floor.covariance, given_.covariance, rtol=1e-9)  # the floor
    noisy = exact + np.random.default_rng(0).normal(0.0, 1.0, (4, 2))
    pose = estimate_marker_pose(noisy, L, PINHOLE)
    sigma = pose.reprojection_rms * np.sqrt(2.0)  # sqrt(SSE / (8 - 6)), SSE = 4 rms^2
    expected = estimate_marker_pose(noisy, L, PINHOLE, pixel_sigma=sigma).covariance
    np.testing.assert_allclose(pose.covariance, expected, rtol=1e-9)


@pytest.mark.parametrize("start", ["planar", "yaw", "all"])
def test_start_modes(poses: types.SimpleNamespace, start: str) -> None:
    R, t = poses.marker_pose(np.radians(10.0), 0.7, 2.5, np.array([0.03, 0.02, 0.7]))
    pose = estimate_marker_pose(corners_of(TUTORIAL, R, t), L, TUTORIAL, start=start)
    assert max(pose_error(pose, R, t)) < 1e-6
    if start == "yaw":
        assert pose.alternative is None  # one start, one solution


def test_opencv_corner_layout_is_accepted(poses: types.SimpleNamespace) -> None:
    R, t = poses.marker_pose(np.radians(20.0), 0.0, 0.0, np.array([0.0, 0.1, 1.0]))
    corners = corners_of(PINHOLE, R, t)
    a = estimate_marker_pose(corners[None], L, PINHOLE)  # (1, 4, 2) from cv2.aruco
    b = estimate_marker_pose(corners.tolist(), L, PINHOLE)
    np.testing.assert_allclose(a.R, b.R)
    np.testing.assert_allclose(a.t, b.t)


def test_params_match_pose_and_covariance_branch(poses: types.SimpleNamespace) -> None:
    rng = np.random.default_rng(9)
    for _ in range(30):
        R, t = poses.random_marker_pose(rng)
        pose = estimate_marker_pose(corners_of(PINHOLE, R, t), L, PINHOLE)
        assert abs(pose.params[4]) <= np.pi / 2
        np.testing.assert_allclose(pose.params[:3], t, atol=1e-9)


GOOD = np.array([[300.0, 200.0], [340.0, 200.0], [340.0, 240.0], [300.0, 240.0]])


@pytest.mark.parametrize(
    ("corners", "match"),
    [
        (GOOD[:3], "corners"),
        (np.zeros((4, 3)), "corners"),
        (np.zeros(8), "corners"),
        (np.where(np.eye(4, 2, dtype=bool), np.nan, GOOD), "corners"),
        (np.where(np.eye(4, 2, dtype=bool), np.inf, GOOD), "corners"),
        (np.full((4, 2), 100.0), "corners"),
        (np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [3.0, 3.0]]), "corners"),
        (GOOD[::-1], "counter-clockwise"),  # a mirrored marker: its pose would face away
    ],
)
def test_bad_corners(corners: np.ndarray, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        estimate_marker_pose(corners, L, PINHOLE)


@pytest.mark.parametrize("length", [0.0, -0.1, np.nan, np.inf])
def test_bad_marker_length(length: float) -> None:
    with pytest.raises(ValueError, match="marker_length"):
        estimate_marker_pose(GOOD, length, PINHOLE)


@pytest.mark.parametrize("length", ["0.1", None, True])
def test_marker_length_of_the_wrong_type(length: object) -> None:
    with pytest.raises(TypeError, match="marker_length"):
        estimate_marker_pose(GOOD, length, PINHOLE)  # type: ignore[arg-type]


def test_bad_camera_and_options() -> None:
    with pytest.raises(TypeError, match="camera"):
        estimate_marker_pose(GOOD, L, PINHOLE.K)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="pixel_sigma"):
        estimate_marker_pose(GOOD, L, PINHOLE, pixel_sigma=0.0)
    with pytest.raises(ValueError, match="max_iter"):
        estimate_marker_pose(GOOD, L, PINHOLE, max_iter=0)
    with pytest.raises(ValueError, match="start"):
        estimate_marker_pose(GOOD, L, PINHOLE, start="ippe")


def test_pose_error_inputs() -> None:
    pose = Pose(np.eye(3), np.zeros(3))
    assert pose_error(pose, np.eye(3), [0.0, 0.0, 1.0]) == (0.0, 1.0)
    with pytest.raises(ValueError, match="R_true"):
        pose_error(pose, np.eye(2), np.zeros(3))
    with pytest.raises(ValueError, match="t_true"):
        pose_error(pose, np.eye(3), np.zeros(2))


def test_corners_too_narrow_for_pixel_coordinates_are_refused() -> None:
    with pytest.raises(TypeError, match="wrap"):
        estimate_marker_pose(GOOD.astype(np.uint8), L, PINHOLE)  # 300 px would read as 44
    assert estimate_marker_pose(GOOD.astype(np.int32), L, PINHOLE) is not None
