"""Starting poses (IPPE planar solutions, the report's yaw seeds), the Gauss-Newton
refinement and the Euler helpers."""

from __future__ import annotations

import math
import types

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from visloc.pose import (
    Camera,
    estimate_marker_pose,
    euler_to_matrix,
    marker_object_points,
    matrix_to_euler,
    planar_solutions,
    refine_params,
    rotation_angle,
    yaw_seed_start,
    yaw_seeds,
)
from visloc.pose.gauss_newton import reprojection_residuals, residuals_and_jacobian
from visloc.pose.planar import _centre_jacobian
from visloc.types import Pose

CAM = Camera(np.array([[600.0, 0.0, 319.5], [0.0, 600.0, 239.5], [0.0, 0.0, 1.0]]))
L = 0.1
OBJ = marker_object_points(L)


def normalized_corners(R: np.ndarray, t: np.ndarray, length: float = L) -> np.ndarray:
    p = marker_object_points(length) @ R.T + t
    return p[:, :2] / p[:, 2:]


def errors(params: np.ndarray, R: np.ndarray, t: np.ndarray) -> tuple[float, float]:
    return rotation_angle(euler_to_matrix(params).T @ R), float(np.linalg.norm(params[:3] - t))


# ---------------------------------------------------------------------------- rotations
def test_euler_convention_is_zyx() -> None:
    rng = np.random.default_rng(0)
    for phi, theta, psi in rng.uniform(-3, 3, (20, 3)):
        ref = Rotation.from_euler("ZYX", [psi, theta, phi]).as_matrix()
        np.testing.assert_allclose(euler_to_matrix([phi, theta, psi]), ref, atol=1e-12)
        back = matrix_to_euler(ref)
        np.testing.assert_allclose(euler_to_matrix(back), ref, atol=1e-12)
        np.testing.assert_allclose(back, Pose(ref, np.zeros(3)).euler_zyx, atol=1e-12)
    assert euler_to_matrix(np.zeros((2, 5, 6))).shape == (2, 5, 3, 3)


def test_matrix_to_euler_at_gimbal_lock_rebuilds_the_matrix() -> None:
    # cos(theta) exactly 0: the yaw used to be dropped (atan2(0, 0)); now phi = 0 as scipy has it
    from visloc.pose.rotations import matrix_to_euler_list

    c, s = math.cos(0.5), math.sin(0.5)
    for sign in (1.0, -1.0):
        R = np.array([[0.0, -s, sign * c], [0.0, c, sign * s], [-sign, 0.0, 0.0]])  # Rz(0.5) Ry(sign pi/2)
        for e in (matrix_to_euler(R), matrix_to_euler(np.stack([R, np.eye(3)]))[0], matrix_to_euler_list(R[None])[0]):
            np.testing.assert_allclose(e, [0.0, sign * math.pi / 2, 0.5], atol=1e-15)
            assert rotation_angle(euler_to_matrix(e).T @ R) < 1e-12


def test_one_rotation_converts_as_many_do_bit_for_bit() -> None:
    # euler_to_matrix and matrix_to_euler have a scalar path for one rotation: the same values
    rng = np.random.default_rng(5)
    angles = rng.uniform(-4.0, 4.0, (400, 3))
    angles[:20, 1] = math.pi / 2
    mats = euler_to_matrix(angles)
    mats[20:40] = np.round(mats[20:40])  # some exact entries (gimbal lock among them)
    many = matrix_to_euler(mats)
    for a, R, e, M in zip(angles, euler_to_matrix(angles), many, mats, strict=True):
        assert np.array_equal(euler_to_matrix(a), R)
        assert np.array_equal(euler_to_matrix(np.concatenate([[1.0, 2.0, 3.0], a])), R)  # (6,): the last three
        assert np.array_equal(matrix_to_euler(M), e)
    assert matrix_to_euler(mats[0]).shape == (3,)
    with pytest.raises(IndexError):
        euler_to_matrix(np.zeros(2))


def test_rotation_angle_is_accurate_near_zero_and_pi() -> None:
    for angle in (0.0, 1e-9, 1e-4, 1.0, math.pi - 1e-7, math.pi):
        R = Rotation.from_rotvec(angle * np.array([0.6, 0.0, 0.8])).as_matrix()
        assert rotation_angle(R) == pytest.approx(angle, rel=1e-6, abs=1e-15)
    with pytest.raises(ValueError):
        rotation_angle(np.eye(2))


# ---------------------------------------------------------------------------- planar (IPPE)
def test_centre_jacobian_matches_the_homography(poses: types.SimpleNamespace) -> None:
    rng = np.random.default_rng(1)
    square = np.array([[-1.0, 1.0], [1.0, 1.0], [1.0, -1.0], [-1.0, -1.0]])
    for _ in range(20):
        R, t = poses.random_marker_pose(rng)
        xy = normalized_corners(R, t)
        u0, v0, J = _centre_jacobian(xy)
        H = cv2.findHomography(square, xy)[0]  # float64; exact for four points
        np.testing.assert_allclose([u0, v0], H[:2, 2] / H[2, 2], atol=1e-9)
        Jh = (H[:2, :2] - np.outer(H[:2, 2], H[2, :2]) / H[2, 2]) / H[2, 2]
        np.testing.assert_allclose(J, Jh, atol=1e-7)


def test_planar_solutions_contain_the_truth(poses: types.SimpleNamespace) -> None:
    rng = np.random.default_rng(2)
    for _ in range(100):
        R, t = poses.random_marker_pose(rng)
        Rs, ts = planar_solutions(normalized_corners(R, t), L)
        for Rk in Rs:
            np.testing.assert_allclose(Rk @ Rk.T, np.eye(3), atol=1e-12)
            assert np.linalg.det(Rk) == pytest.approx(1.0)
        k = int(np.argmin([rotation_angle(Rk.T @ R) for Rk in Rs]))
        assert rotation_angle(Rs[k].T @ R) < 1e-9
        np.testing.assert_allclose(ts[k], t, atol=1e-9)


def test_planar_solutions_coincide_face_on(poses: types.SimpleNamespace) -> None:
    R, t = poses.marker_pose(0.0, 0.0, 1.0, np.array([0.0, 0.0, 1.0]))
    Rs, _ = planar_solutions(normalized_corners(R, t), L)
    assert rotation_angle(Rs[0].T @ Rs[1]) < 1e-9


def test_planar_solutions_degenerate() -> None:
    with pytest.raises(np.linalg.LinAlgError):
        planar_solutions(np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [3.0, 3.0]]), L)


# ---------------------------------------------------------------------------- yaw seeds
def test_yaw_seeds_are_the_reports_four_guesses(poses: types.SimpleNamespace) -> None:
    R, t = poses.marker_pose(0.0, 0.0, 0.0, np.array([0.0, 0.0, 1.5]))
    seeds = yaw_seeds(normalized_corners(R, t), L)
    assert seeds.shape == (4, 6)
    np.testing.assert_allclose(seeds[:, 5], np.radians([0, 90, 180, 270]))
    np.testing.assert_allclose(seeds[:, 3:5], [[math.pi, 0.0]] * 4)
    # face-on on the optical axis: the first guess is the pose itself
    assert max(errors(seeds[0], R, t)) < 1e-12


@pytest.mark.parametrize("yaw_deg", [0, 30, 100, 200, 290])
def test_yaw_seed_start_picks_the_nearest_yaw(poses: types.SimpleNamespace, yaw_deg: float) -> None:
    R, t = poses.marker_pose(np.radians(5.0), 1.0, np.radians(yaw_deg), np.array([0.1, 0.0, 1.0]))
    seed = yaw_seed_start(normalized_corners(R, t), L)
    # the face-on guesses turn about the optical axis by -psi relative to the marker's yaw
    turn = (seed[5] + np.radians(yaw_deg) + np.pi) % (2 * np.pi) - np.pi
    assert abs(turn) <= np.radians(45.0) + 0.1


@pytest.mark.parametrize("tilt_deg", [0.0, 5.0, 10.0, 15.0])
@pytest.mark.parametrize("tilt_dir", [0.0, 1.6, 3.5])
def test_yaw_seed_refinement_converges_near_face_on(
    poses: types.SimpleNamespace, tilt_deg: float, tilt_dir: float
) -> None:
    # the report's method alone (Appendix G): best of four yaw guesses, then Gauss-Newton
    for yaw_deg in range(0, 360, 15):
        for dist in (0.5, 1.0):
            R, t = poses.marker_pose(
                np.radians(tilt_deg), tilt_dir, np.radians(yaw_deg), np.array([0.05, -0.04, dist])
            )
            xy = normalized_corners(R, t)
            params, sse = refine_params(yaw_seed_start(xy, L), OBJ, xy, fx=600.0, fy=600.0)
            rot, trans = errors(params, R, t)
            assert rot < 1e-6 and trans < 1e-6 and sse < 1e-12


def test_yaw_seed_alone_can_land_on_the_flip(poses: types.SimpleNamespace) -> None:
    # at larger tilts the face-on guess often ends in the mirror minimum: why the planar
    # solutions are the default starts
    rng = np.random.default_rng(4)
    truth = flip = 0
    for _ in range(200):
        R, t = poses.random_marker_pose(rng, max_tilt_deg=60.0)
        xy = normalized_corners(R, t)
        params, _ = refine_params(yaw_seed_start(xy, L), OBJ, xy, fx=600.0, fy=600.0)
        best = estimate_marker_pose(CAM.project(OBJ @ R.T + t), L, CAM)
        if max(errors(params, R, t)) < 1e-6:
            truth += 1
        elif best.alternative is not None and (
            rotation_angle(euler_to_matrix(params).T @ best.alternative.R) < 1e-2
        ):
            flip += 1
    assert truth >= 120 and flip >= 20
    assert truth + flip >= 180


# ---------------------------------------------------------------------------- Gauss-Newton
def test_analytic_jacobian_matches_finite_differences() -> None:
    rng = np.random.default_rng(5)
    X = rng.uniform(-0.3, 0.3, (3, 7))
    xy = rng.uniform(-0.2, 0.2, (2, 7))
    f = np.array([[600.0], [580.0]])
    params = np.column_stack([rng.uniform(-0.2, 0.2, (3, 3)), rng.uniform(-3, 3, (3, 3))])
    params[:, 2] += 2.0
    E = residuals_and_jacobian(params, X, xy, f)
    np.testing.assert_allclose(E[..., 6], reprojection_residuals(params, X, xy, f), atol=1e-12)
    for k in range(6):
        d = np.zeros(6)
        d[k] = 1e-6
        num = (
            reprojection_residuals(params + d, X, xy, f)
            - reprojection_residuals(params - d, X, xy, f)
        ) / 2e-6
        np.testing.assert_allclose(E[..., k], num, rtol=1e-5, atol=1e-5)


def test_points_behind_the_camera_give_inf() -> None:
    params = np.array([[0.0, 0.0, 0.05, math.pi, 0.0, 0.0], [0.0, 0.0, 1.0, math.pi, 0.0, 0.0]])
    X = np.array([[0.0, 0.0, 0.1], [0.1, 0.0, -0.1]]).T  # z_cam = 0.05 - z_obj
    r = reprojection_residuals(params, X, np.zeros((2, 2)), np.ones((2, 1)))
    assert np.isinf(r[0]).all() and np.isfinite(r[1]).all()


def test_refine_params_on_a_3d_point_set() -> None:
    rng = np.random.default_rng(6)
    X = rng.uniform(-0.5, 0.5, (10, 3))
    truth = np.array([0.1, -0.2, 3.0, 0.3, -0.2, 1.0])
    p = X @ euler_to_matrix(truth).T + truth[:3]
    xy = p[:, :2] / p[:, 2:]
    start = truth + np.array([0.05, -0.05, 0.3, 0.1, 0.1, -0.2])
    params, sse = refine_params(start, X, xy, fx=600.0, fy=600.0)
    np.testing.assert_allclose(params, truth, atol=1e-9)
    assert sse < 1e-16
    batch, sses = refine_params(np.stack([start, truth]), X, xy)
    assert batch.shape == (2, 6) and sses.shape == (2,)
    with pytest.raises(ValueError, match="params"):
        refine_params(np.zeros(5), X, xy)
    with pytest.raises(ValueError, match="object_points"):
        refine_params(start, X[:, :2], xy)
    with pytest.raises(ValueError, match="xy"):
        refine_params(start, X, xy[:5])


def test_refine_params_max_iter_must_be_a_whole_number(poses: types.SimpleNamespace) -> None:
    # 1.5 used to be truncated to 1, True taken as 1, and -1 failed on another argument's shape
    R, t = poses.marker_pose(0.2, 0.3, 0.4, np.array([0.05, -0.04, 0.8]))
    xy = normalized_corners(R, t)
    start = yaw_seed_start(xy, L)
    np.testing.assert_array_equal(refine_params(start, OBJ, xy, fx=600.0, fy=600.0, max_iter=5.0)[0],
                                  refine_params(start, OBJ, xy, fx=600.0, fy=600.0, max_iter=5)[0])
    for bad in (1.5, True, -1, "3"):
        with pytest.raises(ValueError, match="max_iter"):
            refine_params(start, OBJ, xy, fx=600.0, fy=600.0, max_iter=bad)
