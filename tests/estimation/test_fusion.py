"""The one fusion of map-pose fixes and the accelerometer (visloc.estimation.fusion)."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from visloc.estimation import MapFixFusion, PositionVelocityKF


def test_the_accelerometer_is_turned_into_the_filters_axes_and_gravity_added():
    R = Rotation.from_euler("xyz", [10, -20, 35], degrees=True).as_matrix()
    a_true = np.array([0.3, -0.2, 0.1])
    f = R.T @ (a_true - np.array([0.0, 0.0, -9.81]))  # what the sensor reads: f = R^T (a - g)
    fusion = MapFixFusion(initial_position=np.zeros(3), initial_velocity=np.zeros(3), initial_std=0.01)
    ref = PositionVelocityKF(3, model="cv", accel_noise=2.0, initial_position=np.zeros(3),
                             initial_velocity=np.zeros(3), initial_std=0.01)
    for t in np.arange(0.0, 1.0001, 0.01):
        fusion.predict(t, f, R, accel_std=0.05)
        ref.predict(t, accel=a_true, accel_std=0.05)
    np.testing.assert_allclose(fusion.velocity, a_true * 1.0, atol=1e-9)
    np.testing.assert_allclose(fusion.position, ref.position, atol=1e-12)
    with pytest.raises(ValueError, match="attitude"):
        fusion.predict(1.1, f)


def test_a_fix_counts_at_least_the_floor_and_the_gate_rejects_a_wild_one():
    fusion = MapFixFusion(min_fix_std=0.002, fix_std=0.005)
    fusion.predict(0.0)
    assert fusion.fix([1.0, 2.0, 0.5], np.zeros((3, 3)))  # a perfect-looking fix still has 2 mm
    std_floor = fusion.position_std
    np.testing.assert_allclose(std_floor, 0.002, rtol=0.05)
    fusion.predict(0.1)
    assert fusion.fix([1.0, 2.0, 0.5])  # no covariance: 5 mm
    fusion.predict(0.2)
    assert not fusion.fix([3.0, 2.0, 0.5])  # 2 m away: the gate
    assert (fusion.fixes, fusion.rejected) == (2, 1)


def test_position_std_is_the_prior_s_before_the_first_fix():
    fusion = MapFixFusion()
    np.testing.assert_array_equal(fusion.position_std, np.full(3, 1.0e3))
    fusion = MapFixFusion(initial_position=np.zeros(3), initial_std=(0.1, 1.0))
    np.testing.assert_allclose(fusion.position_std, 0.1)
