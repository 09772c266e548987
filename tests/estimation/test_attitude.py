"""Accelerometer tilt, Q(lambda), gyro integration and the complementary filter (report §3.1)."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from tests.estimation.conftest import G, angle_error_deg, static_accel
from visloc.estimation import (
    ComplementaryFilter,
    GyroIntegrator,
    accel_tilt,
    euler_rates_matrix,
)

DEG = math.radians(1.0)


def test_level_imu_reads_minus_g_on_z_and_gives_zero_tilt():
    roll, pitch = accel_tilt([0.0, 0.0, -G])
    assert roll == 0.0 and pitch == 0.0


def test_sign_conventions():
    # right wing down (positive roll): gravity gains a +y body component, so f_y < 0
    f_roll = static_accel(math.radians(15), 0.0)
    assert f_roll[1] < 0
    assert accel_tilt(f_roll)[0] == pytest.approx(math.radians(15), abs=1e-12)
    # nose up (positive pitch): gravity gains a -x body component, so f_x > 0
    f_pitch = static_accel(0.0, math.radians(10))
    assert f_pitch[0] > 0
    assert accel_tilt(f_pitch)[1] == pytest.approx(math.radians(10), abs=1e-12)
    # the same convention as scipy's intrinsic Z-Y-X: R = Rz(psi) Ry(theta) Rx(phi)
    r = Rotation.from_euler("ZYX", [0.3, 0.2, -0.25]).as_matrix()
    f = r.T @ np.array([0.0, 0.0, -G])  # f = R^T (a - g e3) at rest
    assert np.allclose(accel_tilt(f), (-0.25, 0.2), atol=1e-12)


def test_static_tilt_and_upside_down():
    for roll, pitch in [(0.3, -0.2), (-1.0, 0.5), (2.8, 0.1), (-2.5, -1.2)]:
        assert np.allclose(accel_tilt(static_accel(roll, pitch)), (roll, pitch), atol=1e-12)


@given(st.floats(-3.1, 3.1), st.floats(-1.5, 1.5), st.floats(0.5, 30.0))
def test_tilt_roundtrip_any_magnitude(roll, pitch, g):
    assert np.allclose(accel_tilt(static_accel(roll, pitch, g)), (roll, pitch), atol=1e-9)


def test_accel_tilt_batch_and_errors():
    f = np.array([static_accel(0.1, 0.2), static_accel(-0.3, 0.05)])
    roll, pitch = accel_tilt(f)
    assert np.allclose(roll, [0.1, -0.3]) and np.allclose(pitch, [0.2, 0.05])
    with pytest.raises(ValueError, match="accel"):
        accel_tilt([0.0, 0.0])
    with pytest.raises(ValueError, match="accel"):
        accel_tilt([np.nan, 0.0, -G])
    with pytest.raises(ValueError, match="accel"):
        accel_tilt([0.0, 0.0, 0.0])


def test_euler_rates_matrix_matches_rotation_kinematics():
    roll, pitch, yaw = 0.4, -0.3, 1.1
    omega = np.array([0.2, -0.5, 0.7])
    h = 1e-6
    r0 = Rotation.from_euler("ZYX", [yaw, pitch, roll])
    # body rates: R(t + h) = R(t) expm(omega^ h)
    r1 = r0 * Rotation.from_rotvec(omega * h)
    y1, p1, r1_ = r1.as_euler("ZYX")
    numeric = (np.array([r1_, p1, y1]) - [roll, pitch, yaw]) / h
    assert np.allclose(euler_rates_matrix(roll, pitch) @ omega, numeric, atol=1e-5)
    assert np.allclose(euler_rates_matrix(0.0, 0.0), np.eye(3))
    with pytest.raises(ValueError, match="pitch"):
        euler_rates_matrix(0.0, math.pi / 2)


def test_gyro_integrator_follows_exact_rates_and_drifts_with_bias(ten_minutes):
    s = ten_minutes
    n = 200 * 60  # first minute
    exact = GyroIntegrator(s.roll[0], s.pitch[0], s.yaw[0]).run(s.body_rates[:n], s.dt)
    err = angle_error_deg(exact[:, :2], s.attitude[:n])
    assert np.abs(err).max() < 0.2, f"forward-Euler error {np.abs(err).max():.3f} deg"
    biased = GyroIntegrator(s.roll[0], s.pitch[0], s.yaw[0]).run(s.gyro[:n], s.dt)
    drift = angle_error_deg(biased[-1, 0], s.roll[n - 1])
    assert abs(drift) > 100, f"roll drift after 60 s with 0.05 rad/s bias: {drift:.1f} deg"


def test_gyro_integrator_update_skip_and_dt():
    gi = GyroIntegrator()
    assert gi.update([0.1, 0.0, 0.0], 0.5) == pytest.approx((0.05, 0.0, 0.0))
    assert gi.update([np.nan, 0.0, 0.0], 0.5) == pytest.approx((0.05, 0.0, 0.0))
    assert gi.skipped == 1
    with pytest.raises(ValueError, match="dt"):
        gi.update([0.0, 0.0, 0.0], 0.0)
    gi.reset(0.1, 0.2, 0.3)
    assert (gi.roll, gi.pitch, gi.yaw) == (0.1, 0.2, 0.3)


def test_complementary_static_tilt_converges():
    f = ComplementaryFilter(1.0, initial=(0.0, 0.0))
    acc = static_accel(math.radians(12), math.radians(-7))
    for _ in range(400):  # 2 s at 200 Hz, c = 2 pi rad/s
        roll, pitch = f.update([0.0, 0.0, 0.0], acc, 0.005)
    assert roll == pytest.approx(math.radians(12), abs=1e-4)
    assert pitch == pytest.approx(math.radians(-7), abs=1e-4)


def test_complementary_is_first_order_lowpass_on_accel():
    """Report eq. 3.5: a step in the accelerometer angle reaches 1 - e^-1 after 1 / c seconds."""
    c = 2.0
    f = ComplementaryFilter(gain=c, initial=(0.0, 0.0))
    acc = static_accel(0.0, 0.1)
    n = 500
    for _ in range(n):
        f.update([0.0, 0.0, 0.0], acc, 1.0 / (c * n))
    assert f.pitch == pytest.approx(0.1 * (1 - math.exp(-1)), rel=1e-9)
    assert f.c == pytest.approx(c) and ComplementaryFilter(0.5).c == pytest.approx(math.pi)


def test_complementary_plain_gain_bias_error_is_b_over_c():
    """With only the gain c, a gyro bias b leaves a steady error of about b / c (report §3.1.3)."""
    f = ComplementaryFilter(gain=2.0, initial=(0.0, 0.0))
    acc = static_accel(0.0, 0.0)
    for _ in range(4000):
        f.update([0.05, 0.0, 0.0], acc, 0.005)
    assert f.roll == pytest.approx(0.05 / 2.0, rel=1e-2)
    g = ComplementaryFilter(gain=2.0, bias_gain=1.0, initial=(0.0, 0.0))
    for _ in range(8000):
        g.update([0.05, -0.03, 0.0], acc, 0.005)
    assert abs(g.roll) < 1e-4 and abs(g.pitch) < 1e-4
    assert np.allclose(g.bias[:2], [0.05, -0.03], atol=1e-4)


def test_complementary_first_sample_initialises_and_reset():
    f = ComplementaryFilter(0.1)
    assert not f.initialised
    acc = static_accel(0.2, -0.1)
    assert f.update([1.0, 1.0, 1.0], acc, 0.01) == pytest.approx((0.2, -0.1))
    f.update([0.0, 0.0, 0.0], static_accel(0.0, 0.0), 0.01)
    f.reset(0.5, -0.25)
    assert (f.roll, f.pitch) == (0.5, -0.25)
    assert np.array_equal(f.attitude, [0.5, -0.25])
    f.reset(0.0, 0.0, bias=[0.01, 0.02, 0.03])
    assert np.array_equal(f.bias, [0.01, 0.02, 0.03])


def test_complementary_skips_non_finite_samples_and_never_goes_nan():
    f = ComplementaryFilter(0.5, initial=(0.1, 0.1))
    acc = static_accel(0.1, 0.1)
    before = (f.roll, f.pitch)
    assert f.update([np.nan, 0.0, 0.0], acc, 0.01) == before
    assert f.update([0.0, 0.0, 0.0], [0.0, np.inf, -G], 0.01) == before
    assert f.skipped == 2
    gyro = np.zeros((10, 3))
    accel = np.tile(acc, (10, 1))
    gyro[3, 1] = np.nan
    accel[6, 2] = -np.inf
    out = f.run(gyro, accel, 0.01)
    assert f.skipped == 4 and np.all(np.isfinite(out))
    assert np.array_equal(out[3], out[2]) and np.array_equal(out[6], out[5])


def test_run_equals_update_loop(ten_minutes):
    s = ten_minutes
    n = 2000
    a = ComplementaryFilter(0.05, bias_gain=0.01)
    batch = a.run(s.gyro[:n], s.accel[:n], s.dt)
    b = ComplementaryFilter(0.05, bias_gain=0.01)
    loop = np.array([b.update(g, f, s.dt) for g, f in zip(s.gyro[:n], s.accel[:n])])
    assert np.array_equal(batch, loop)


@pytest.mark.parametrize("dt", [0.0, -0.01, float("nan"), float("inf")])
def test_dt_must_be_positive_and_finite(dt):
    f = ComplementaryFilter(0.5)
    with pytest.raises(ValueError, match="dt"):
        f.update([0.0, 0.0, 0.0], [0.0, 0.0, -G], dt)
    with pytest.raises(ValueError, match="dt"):
        f.run(np.zeros((3, 3)), np.tile([0.0, 0.0, -G], (3, 1)), [0.01, dt, 0.01])


def test_bad_arguments_are_named():
    with pytest.raises(ValueError, match="crossover_hz"):
        ComplementaryFilter(-1.0)
    with pytest.raises(ValueError, match="exactly one"):
        ComplementaryFilter(1.0, gain=2.0)
    with pytest.raises(ValueError, match="gyro"):
        ComplementaryFilter(1.0).update([0.0, 0.0], [0.0, 0.0, -G], 0.01)
    with pytest.raises(ValueError, match="accel"):
        ComplementaryFilter(1.0).run(np.zeros((3, 3)), np.zeros((2, 3)), 0.01)
    with pytest.raises(TypeError, match="initial"):
        ComplementaryFilter(1.0, initial=0.3)
    with pytest.raises(TypeError, match="gyro"):
        ComplementaryFilter(1.0).update("abc", [0.0, 0.0, -G], 0.01)


def test_free_fall_sample_integrates_gyro_only():
    f = ComplementaryFilter(1.0, initial=(0.0, 0.0))
    f.update([0.2, 0.0, 0.0], [0.0, 0.0, 0.0], 0.1)
    assert f.roll == pytest.approx(0.2 * (1 - math.exp(-2 * math.pi * 0.1)) / (2 * math.pi))
    assert f.skipped == 0


def test_accel_tilt_type_error_names_accel():
    with pytest.raises(TypeError, match="accel"):
        accel_tilt("abc")
    with pytest.raises(TypeError, match="accel"):
        accel_tilt([object(), 1.0, 2.0])


def test_complementary_reset_checks_the_bias_before_changing_anything():
    f = ComplementaryFilter(0.1, initial=(0.1, 0.2), bias=[0.01, 0.02, 0.03])
    for bad, exc in (([0.0, 0.0], ValueError), ([0.0, np.nan, 0.0], ValueError), ("abc", TypeError)):
        with pytest.raises(exc, match="bias"):
            f.reset(0.5, -0.25, bias=bad)
        assert (f.roll, f.pitch) == (0.1, 0.2)
        assert np.array_equal(f.bias, [0.01, 0.02, 0.03])


def test_complementary_reset_starts_the_fast_start_again():
    acc = static_accel(0.0, 0.0)
    f = ComplementaryFilter(0.01, initial=(0.0, 0.0), settle_seconds=1.0, settle_hz=1.0)
    f.run(np.zeros((300, 3)), np.tile(acc, (300, 1)), 0.01)  # 3 s: past the fast start
    assert f.elapsed == pytest.approx(3.0)
    f.reset(0.2, 0.0)
    assert f.elapsed == 0.0
    f.update([0.0, 0.0, 0.0], acc, 0.01)  # at 1 Hz, not 0.01 Hz
    assert f.roll == pytest.approx(0.2 * math.exp(-2 * math.pi * 1.0 * 0.01))


def test_gyro_integrator_skips_a_step_that_overflows():
    # a huge rate times dt used to give NaN angles for good, uncounted
    g = GyroIntegrator()
    assert g.update([1e308, 0.0, 0.0], 10.0) == (0.0, 0.0, 0.0) and g.skipped == 1
    assert g.update([0.1, 0.0, 0.0], 1.0) == pytest.approx((0.1, 0.0, 0.0))


def test_accel_tilt_of_huge_readings_is_the_tilt_of_their_direction():
    # the norm's squares overflowed to inf: pitch came out 0
    big, unit = accel_tilt([3e200, 3e200, -3e200]), accel_tilt([3.0, 3.0, -3.0])
    assert big == pytest.approx(unit, rel=1e-12) and big[1] == pytest.approx(math.asin(1 / math.sqrt(3)))
