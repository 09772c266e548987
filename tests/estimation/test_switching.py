"""The report's switching estimator (eqs. 3.6-3.11) and the failure it was dropped for."""

import math

import numpy as np
import pytest

from tests.estimation.conftest import G, angle_error_deg, static_accel
from visloc.estimation import ComplementaryFilter, GyroIntegrator, SwitchingFilter

DT = 0.005


def test_resets_only_when_all_three_tests_hold():
    sw = SwitchingFilter(0.1, 5.0, initial=(0.0, 0.0))
    tilt = static_accel(0.2, -0.1)
    sw.update([0.0, 0.0, 0.0], tilt, DT)  # first sample: no norm history for eq. 3.8 -> gyro
    assert (sw.roll, sw.pitch) == (0.0, 0.0) and sw.resets == 0
    sw.update([0.0, 0.0, 0.0], tilt, DT)  # (3.6)-(3.8) hold -> lambda_hat = lambda_a (3.9)
    assert (sw.roll, sw.pitch) == pytest.approx((0.2, -0.1)) and sw.resets == 1
    sw.reset(0.0, 0.0)
    sw.update([0.0, 0.0, 0.0], 1.05 * tilt, DT)  # |f| - g = 0.49 > delta_n (3.7 fails)
    sw.update([0.0, 0.0, 0.0], 1.05 * tilt, DT)
    assert (sw.roll, sw.pitch) == (0.0, 0.0)
    sw.update([0.0, 0.0, 0.0], 1.005 * tilt, DT)  # (3.7) holds, but |f| changed at 9.8 m/s^3
    assert (sw.roll, sw.pitch) == (0.0, 0.0)
    upside_down = -static_accel(0.0, 0.0)  # f_z > 0, i.e. the report's a_z < 0 (3.6 fails)
    sw.update([0.0, 0.0, 0.0], upside_down, DT)
    sw.update([0.0, 0.0, 0.0], upside_down, DT)
    assert (sw.roll, sw.pitch) == (0.0, 0.0) and sw.resets == 1


def test_integrates_gyro_otherwise():
    sw = SwitchingFilter(0.1, 5.0, initial=(0.0, 0.0))
    for _ in range(100):  # 0.5 s of 0.2 rad/s roll rate under a disturbed norm
        sw.update([0.2, 0.0, 0.0], [0.0, 0.0, -12.0], DT)
    assert sw.roll == pytest.approx(0.1) and sw.pitch == pytest.approx(0.0)


def test_bias_is_reset_away_at_rest():
    """Report Fig. 3.5: at rest the resets stop the drift the integrated gyro shows."""
    rng = np.random.default_rng(2)
    n = 2000
    gyro = np.array([0.05, -0.03, 0.02]) + 0.005 * rng.standard_normal((n, 3))
    accel = static_accel(0.1, 0.05) + 0.02 * rng.standard_normal((n, 3))
    sw = SwitchingFilter(0.1, 20.0)
    est = sw.run(gyro, accel, DT)
    drift = GyroIntegrator(0.1, 0.05).run(gyro, DT)
    assert np.abs(angle_error_deg(est[-1], [0.1, 0.05])).max() < 0.5
    assert np.abs(angle_error_deg(drift[-1, :2], [0.1, 0.05])).max() > 10
    assert sw.resets > n // 2


def _accelerate_forward_keeping_norm_g(peak=3.0, ramp=0.5, hold=2.0, rest=1.0):
    """A level, non-rotating drone accelerating forward while sinking slightly, such that the
    specific force keeps |f| = g exactly: a = (a_x, 0, g - sqrt(g^2 - a_x^2)) (NED)."""
    t = np.arange(0.0, rest + 2 * ramp + hold + rest, DT)
    x = np.clip((t - rest) / ramp, 0, 1) - np.clip((t - rest - ramp - hold) / ramp, 0, 1)
    a_x = peak * x * x * (3 - 2 * x)  # smooth up, hold, smooth down
    f = np.column_stack([a_x, np.zeros_like(t), -np.sqrt(G**2 - a_x**2)])  # f = a - g e3
    return f


def test_switching_resets_to_wrong_angle_under_acceleration_with_norm_g():
    """The report's failure (§3.1.5: "it incidentally occurs ... that the wrong angle is
    estimated"): all tests pass, so the filter snaps to the accelerometer's tilt, 17.8 deg off,
    while the complementary filter only creeps away from the truth."""
    f = _accelerate_forward_keeping_norm_g()
    rng = np.random.default_rng(0)
    accel = f + 0.05 * rng.standard_normal(f.shape)
    gyro = 0.005 * rng.standard_normal(f.shape)  # no rotation: truth is level throughout
    assert np.allclose(np.linalg.norm(f, axis=1), G)
    sw = SwitchingFilter(0.1, 30.0)
    cf = ComplementaryFilter(0.01, bias_gain=(2 * math.pi * 0.01) ** 2 / 4)
    hold = np.abs(f[:, 0] - 3.0) < 1e-9  # the 2 s at full acceleration
    sw_pitch = np.degrees(sw.run(gyro, accel, DT)[:, 1])
    cf_pitch = np.degrees(cf.run(gyro, accel, DT)[:, 1])
    wrong = math.degrees(math.asin(3.0 / G))
    sw_err, cf_err = np.median(np.abs(sw_pitch[hold])), np.abs(cf_pitch).max()
    msg = (f"pitch error while accelerating: switching {sw_err:.2f} deg (median), "
           f"complementary {cf_err:.2f} deg (max); accelerometer tilt {wrong:.2f} deg")
    assert sw_err == pytest.approx(wrong, abs=0.3), msg
    assert cf_err < 0.25 * sw_err, msg
    cf_fast = ComplementaryFilter(0.1)  # a 10x faster crossover follows more, still less
    cf_fast_err = np.abs(np.degrees(cf_fast.run(gyro, accel, DT)[:, 1])).max()
    assert cf_fast_err < sw_err, f"{msg}; complementary 0.1 Hz {cf_fast_err:.2f} deg"


def test_switching_checks_and_skips():
    with pytest.raises(ValueError, match="delta_n"):
        SwitchingFilter(0.0, 1.0)
    with pytest.raises(ValueError, match="delta_d"):
        SwitchingFilter(0.1, -1.0)
    sw = SwitchingFilter(0.1, 5.0, initial=(0.0, 0.0))
    assert sw.update([0.0, np.nan, 0.0], [0.0, 0.0, -G], DT) == (0.0, 0.0)
    assert sw.skipped == 1
    with pytest.raises(ValueError, match="dt"):
        sw.update([0.0, 0.0, 0.0], [0.0, 0.0, -G], -DT)
