"""The synthetic IMU stream's truth is self-consistent."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from visloc.synth.imu import imu_stream


def _rot(s, idx):
    return Rotation.from_euler("ZYX", np.column_stack([s.yaw, s.pitch, s.roll])[idx]).as_matrix()


def test_shapes_bounds_and_noise():
    s = imu_stream(60.0, 100.0, seed=1)
    n = 6000
    assert s.t.shape == (n,) and s.gyro.shape == (n, 3) and s.accel.shape == (n, 3)
    assert s.body_rates.shape == (n, 3) and s.attitude.shape == (n, 2)
    assert np.abs(s.roll).max() <= math.radians(20.0) + 1e-12
    assert np.abs(s.pitch).max() <= math.radians(20.0) + 1e-12
    gyro_err = s.gyro - s.body_rates - s.gyro_bias
    assert np.allclose(gyro_err.mean(axis=0), 0.0, atol=3e-4)
    assert np.allclose(gyro_err.std(axis=0), 0.005, rtol=0.05)
    horiz = s.accel_ned[:, :2].std(axis=0)
    assert np.all((horiz > 1.0) & (horiz < 3.5)), horiz


def test_body_rates_match_rotation_derivative():
    """omega^ = R^T dR/dt, checked by central differences of the analytic attitude."""
    s = imu_stream(20.0, 1000.0, seed=3)
    idx = np.arange(1, len(s.t) - 1, 97)
    r0, rm, rp = _rot(s, idx), _rot(s, idx - 1), _rot(s, idx + 1)
    skew = np.einsum("nji,njk->nik", r0, (rp - rm) / (2 * s.dt))
    omega = np.column_stack([skew[:, 2, 1], skew[:, 0, 2], skew[:, 1, 0]])
    assert np.abs(omega - s.body_rates[idx]).max() < 1e-5


def test_specific_force_is_rotated_acceleration_minus_gravity():
    s = imu_stream(5.0, 50.0, seed=4)
    rot = _rot(s, slice(None))  # body -> NED
    f = np.einsum("nji,nj->ni", rot, s.accel_ned - [0.0, 0.0, 9.81])
    assert np.abs(f - s.specific_force).max() < 1e-12


def test_rest_period_is_still_and_level():
    s = imu_stream(12.0, 100.0, seed=5, rest_seconds=5.0, gyro_noise=0.0, accel_noise=0.0)
    rest = s.t < 5.0
    assert np.all(s.roll[rest] == 0) and np.all(s.pitch[rest] == 0)
    assert np.allclose(s.accel[rest], [0.0, 0.0, -9.81])
    assert np.allclose(s.gyro[rest], s.gyro_bias)
    assert np.abs(s.roll[s.t > 11.0]).max() > 0


def test_seeded_and_checked():
    a = imu_stream(2.0, 50.0, seed=9)
    b = imu_stream(2.0, 50.0, seed=9)
    assert np.array_equal(a.gyro, b.gyro) and np.array_equal(a.accel, b.accel)
    with pytest.raises(ValueError, match="rate_hz"):
        imu_stream(2.0, 0.0, seed=1)
    with pytest.raises(TypeError, match="seed"):
        imu_stream(2.0, 50.0, seed=1.5)
    with pytest.raises(ValueError, match="gyro_bias"):
        imu_stream(2.0, 50.0, seed=1, gyro_bias=(0.1, 0.2))
