"""Shared fixtures and helpers for the estimation tests."""

import math

import numpy as np
import pytest

from visloc.synth.imu import imu_stream

G = 9.81


def static_accel(roll, pitch, g=G):
    """Specific force (NED body axes) of an IMU at rest with the given roll and pitch:
    ``f = -g R^T e3`` (level: ``(0, 0, -g)``)."""
    return -g * np.array([-math.sin(pitch), math.cos(pitch) * math.sin(roll),
                          math.cos(pitch) * math.cos(roll)])


def angle_error_deg(est, truth):
    """Wrapped difference ``est - truth`` in degrees (any matching shapes)."""
    return np.degrees((np.asarray(est) - np.asarray(truth) + np.pi) % (2 * np.pi) - np.pi)


def rms(x):
    return float(np.sqrt(np.mean(np.square(x))))


@pytest.fixture(scope="session")
def ten_minutes():
    """Ten minutes at 200 Hz (120 000 samples): gyro bias (0.05, -0.03, 0.02) rad/s, gyro and
    accelerometer noise, horizontal accelerations of 2 m/s^2 std per axis (0.2-2 Hz); the drone
    sits level for the first 10 s (on the ground before take-off)."""
    return imu_stream(600.0, 200.0, seed=7, rest_seconds=10.0)
