"""The gimbal-stand model (report Appendix C)."""

import math

import numpy as np
import pytest

from visloc.model import ARDRONE2, rotation_matrix
from visloc.model.stand import stand_derivatives, stand_gravity_torque, stand_inertia, stand_linear

P = ARDRONE2
L = 0.05


def test_gravity_torque_is_eq_c2_in_body_axes():
    rng = np.random.default_rng(0)
    e3 = np.array([0.0, 0.0, 1.0])
    for _ in range(10):
        lam = rng.uniform(-0.8, 0.8, 3)
        R = rotation_matrix(lam)
        inertial = -L * np.cross(R @ e3, P.mass * P.g * e3)  # report eq. (C.2)
        np.testing.assert_allclose(stand_gravity_torque(lam, P, L), R.T @ inertial, atol=1e-12)
    # at psi = theta = 0 the roll component is the report's (C.6): m g l sin(phi)
    assert stand_gravity_torque([0.3, 0.0, 0.0], P, L)[0] == pytest.approx(P.mass * P.g * L * math.sin(0.3))
    # no dependence on the yaw
    np.testing.assert_allclose(stand_gravity_torque([0.2, -0.1, 1.0], P, L),
                               stand_gravity_torque([0.2, -0.1, -2.0], P, L), atol=1e-15)


def test_joint_below_tips_over_joint_above_rights():
    tilt = np.array([0.1, 0.0, 0.0, 0.0, 0.0, 0.0])
    assert stand_derivatives(tilt, np.zeros(4), P, l=L)[3] > 0  # falls further
    assert stand_derivatives(tilt, np.zeros(4), P, l=-L)[3] < 0  # swings back
    np.testing.assert_allclose(stand_inertia(P, L), [P.Ixx + P.mass * L**2, P.Iyy + P.mass * L**2, P.Izz])


def test_linear_model_matches_the_jacobian():
    a, b = stand_linear(P, L)
    x0, u0 = np.zeros(6), np.array([P.mass * P.g, 0, 0, 0])
    h = 1e-6
    a_num = np.column_stack([(stand_derivatives(x0 + h * e, u0, P, l=L)
                              - stand_derivatives(x0 - h * e, u0, P, l=L)) / (2 * h) for e in np.eye(6)])
    b_num = np.column_stack([(stand_derivatives(x0, u0 + h * e, P, l=L)
                              - stand_derivatives(x0, u0 - h * e, P, l=L)) / (2 * h) for e in np.eye(4)])
    np.testing.assert_allclose(a, a_num, atol=1e-6)
    np.testing.assert_allclose(b, b_num, atol=1e-6)
    assert np.max(np.linalg.eigvals(a).real) > 0  # upright on the joint: unstable
    assert np.max(np.linalg.eigvals(stand_linear(P, -L)[0]).real) < 1e-9  # hanging: marginal


def test_yaw_torque_and_bad_input():
    d = stand_derivatives(np.zeros(6), [4.0, 0.0, 0.0, 0.01], P, l=L)
    np.testing.assert_allclose(d, [0, 0, 0, 0, 0, 0.01 / P.Izz], atol=1e-15)  # eq. (C.8)
    with pytest.raises(ValueError, match="l"):
        stand_derivatives(np.zeros(6), np.zeros(4), P, l=math.nan)
    with pytest.raises(ValueError, match="state"):
        stand_derivatives(np.zeros(12), np.zeros(4), P, l=L)


def test_numpy_scalar_joint_distances_are_taken():
    # l was checked against int and float only: np.float32(0.1) was "not a finite distance"
    for l in (np.float32(0.1), np.float64(0.1), np.int64(1)):
        np.testing.assert_allclose(stand_inertia(ARDRONE2, l), stand_inertia(ARDRONE2, float(l)))
    with pytest.raises(ValueError, match="l:"):
        stand_inertia(ARDRONE2, True)
