"""Simulated IMU and ultrasound (report §3.1 conventions, eq. 3.12)."""

import numpy as np
import pytest

from visloc.estimation import ultrasound_height
from visloc.model import rotation_matrix
from visloc.sim import Imu, Ultrasound


def test_imu_reads_rates_and_specific_force():
    imu = Imu(gyro_noise=0.0, accel_noise=0.0, gyro_bias=(0.01, 0.0, -0.02))
    s = np.zeros(12)
    s[9:12] = [0.1, -0.2, 0.3]
    gyro, accel = imu.sample(s, np.eye(3), np.zeros(3), 9.81)
    np.testing.assert_allclose(gyro, [0.11, -0.2, 0.28])
    np.testing.assert_allclose(accel, [0.0, 0.0, -9.81])  # level at rest
    s[6] = 0.2  # rolled, hovering: thrust balances gravity in z, the body sees -T/m along its z
    R = rotation_matrix(s[6:9])
    thrust_acc = -R @ np.array([0, 0, 1.0]) * 9.81 / np.cos(0.2)
    _, accel = imu.sample(s, R, thrust_acc + np.array([0, 0, 9.81]), 9.81)
    np.testing.assert_allclose(accel, [0.0, 0.0, -9.81 / np.cos(0.2)], atol=1e-12)
    with pytest.raises(ValueError, match="gyro_bias"):
        Imu(gyro_bias=(0.0, 0.0))


def test_ultrasound_follows_eq_3_12():
    us = Ultrasound(noise=0.0)
    s = np.zeros(12)
    s[2] = -1.2
    reading = us.sample(s, np.eye(3))
    assert ultrasound_height(reading).height == pytest.approx(1.2)
    s[2] = -0.1  # inside the blind zone
    assert us.sample(s, np.eye(3)) == 0.0
    s[2] = -1.0
    tilted = rotation_matrix([0.3, 0.0, 0.0])  # the beam runs along body z: a longer path
    assert ultrasound_height(us.sample(s, tilted)).height == pytest.approx(1.0 / np.cos(0.3))


def test_vision_estimator_takes_the_ultrasound_height():
    from visloc.estimation import ultrasound_reading
    from visloc.pose import GridMap
    from visloc.sim import BottomCamera, VisionEstimator

    camera = BottomCamera(GridMap(4, 4, 0.1, 0.05), "DICT_4X4_50")
    s = np.zeros(12)
    s[2] = -1.0
    est = VisionEstimator(camera, s)
    est.imu(0.0, np.zeros(3), np.array([0.0, 0.0, -9.81]))
    assert est.ultrasound(0.0, ultrasound_reading(1.02))  # 2 cm higher: pulled up
    assert -1.02 < est.state[2] < -1.0
    z = est.state[2]
    assert not est.ultrasound(0.0, 0.0)  # blind zone
    assert not est.ultrasound(0.0, ultrasound_reading(2.0))  # far off the prediction: gated
    assert est.state[2] == z


def test_vision_estimator_imu_refuses_a_bad_sample_without_changing():
    # the clock, the body rates and the attitude used to move before the filter raised
    from visloc.pose import GridMap
    from visloc.sim import BottomCamera, VisionEstimator

    est = VisionEstimator(BottomCamera(GridMap(4, 4, 0.1, 0.05), "DICT_4X4_50"), np.r_[0.0, 0.0, -1.0, np.zeros(9)])
    level = np.array([0.0, 0.0, -9.81])
    est.imu(0.02, np.zeros(3), level)
    before = est.state.copy()
    for t, gyro, accel, match in ((0.01, [1.0, 0.0, 0.0], level, "out-of-order"),
                                  (0.03, [1.0, 0.0, 0.0], [0.0, -9.81], "accel"),
                                  (0.03, [np.nan, 0.0, 0.0], level, "gyro")):
        with pytest.raises(ValueError, match=match):
            est.imu(t, np.array(gyro), np.asarray(accel))
        np.testing.assert_array_equal(est.state, before)
        assert est.kf.t == 0.02
    est.imu(0.03, [0.1, 0.0, 0.0], [0.0, 0.0, -9.81])  # lists are samples too
    assert est.state[6] == pytest.approx(0.001) and est.state[9] == 0.1
