"""The simulated vehicle: RK4 of the rigid body with per-motor propulsion (report eqs. 2.1-2.18)."""

import math

import numpy as np
import pytest

from visloc.model import ARDRONE2, hover_pwm, pwm_bar
from visloc.sim import Vehicle, motor_coefficients

P = ARDRONE2


def _at(z=-1.0):
    s = np.zeros(12)
    s[2] = z
    return s


def test_hover_trim_holds_still():
    v = Vehicle(state=_at())
    trim = np.full(4, hover_pwm(P))
    for _ in range(1000):
        v.step(trim, 0.002)
    np.testing.assert_allclose(v.state, _at(), atol=1e-9)
    assert v.time == pytest.approx(2.0)
    np.testing.assert_allclose(v.inputs, [P.mass * P.g, 0, 0, 0], atol=1e-9)


def test_free_fall_with_motors_off():
    v = Vehicle(state=_at(-10.0))
    for _ in range(100):
        v.step(np.zeros(4), 0.01)
    assert v.state[2] == pytest.approx(-10.0 + 0.5 * P.g * 1.0**2, abs=1e-9)  # z down
    assert v.state[5] == pytest.approx(P.g * 1.0, abs=1e-9)


def test_pure_yaw_torque():
    # motors 2 and 4 spin up, 1 and 3 down by the same squared amount: no thrust change,
    # no roll or pitch torque, tau_z = 4 d dq (report eq. 2.12)
    v = Vehicle(state=_at())
    base = pwm_bar(np.full(4, hover_pwm(P)), P.k)
    dq = 200.0
    pwm = np.sqrt(base + np.array([-dq, dq, -dq, dq])) - P.k
    v.step(pwm, 0.01)
    tau_z = 4 * P.d_mean * dq
    assert v.inputs[0] == pytest.approx(P.mass * P.g)
    np.testing.assert_allclose(v.inputs[1:3], 0.0, atol=1e-12)
    assert v.state[11] == pytest.approx(tau_z / P.Izz * 0.01, rel=1e-9)
    assert v.state[8] == pytest.approx(0.5 * tau_z / P.Izz * 0.01**2, rel=1e-9)
    np.testing.assert_allclose(v.state[[6, 7, 9, 10]], 0.0, atol=1e-15)


def test_motor_lag_approaches_the_command_exponentially():
    v = Vehicle(state=_at(), motor_lag=0.05)
    v.trim(np.full(4, 60.0))
    target = pwm_bar(np.full(4, 70.0), P.k)
    start = pwm_bar(np.full(4, 60.0), P.k)
    v.step(np.full(4, 70.0), 0.05)
    frac = 1 - math.exp(-1.0)
    np.testing.assert_allclose(v._bar, start + frac * (target - start), rtol=1e-12)


def test_pwm_is_saturated_and_a_push_moves_the_body():
    v = Vehicle(state=_at())
    out = v.step(np.array([150.0, -5.0, 50.0, 50.0]), 0.001)
    assert isinstance(out, np.ndarray) and out.shape == (12,) and np.array_equal(out, v.state)  # was a list
    np.testing.assert_allclose(v.pwm, [100.0, 0.0, 50.0, 50.0])
    np.testing.assert_array_equal(v.acceleration([0.0, 0.0, 0.0]), v.acceleration())  # a list force
    w = Vehicle(state=_at())
    w.trim(np.full(4, hover_pwm(P)))
    for _ in range(100):
        w.step(np.full(4, hover_pwm(P)), 0.001, force=[0.0, P.mass, 0.0])  # 1 m/s^2 east
    assert w.state[4] == pytest.approx(0.1, rel=1e-9)


def test_motor_coefficients_at_n_sigma():
    c, d = motor_coefficients(P, 0.0)
    np.testing.assert_allclose(c, P.c_mean)
    np.testing.assert_allclose(d, P.d_mean)
    c, d = motor_coefficients(P, 2.0, seed=5)
    np.testing.assert_allclose(np.abs(c - P.c_mean), 2 * P.c_std, rtol=1e-12)
    np.testing.assert_allclose(np.abs(d - P.d_mean), 2 * P.d_std, rtol=1e-12)
    c2, _ = motor_coefficients(P, 2.0, seed=5)
    np.testing.assert_array_equal(c, c2)
    with pytest.raises(ValueError, match="n_sigma"):
        motor_coefficients(P, 20.0)


def test_bad_input():
    with pytest.raises(ValueError, match="dt"):
        Vehicle().step(np.zeros(4), 0.0)
    with pytest.raises(ValueError, match="pwm"):
        Vehicle().step(np.zeros(3), 0.01)
    with pytest.raises(ValueError, match="motor_lag"):
        Vehicle(motor_lag=-1.0)
    with pytest.raises(ValueError, match="c, d"):
        Vehicle(c=[1e-4, 1e-4, -1e-4, 1e-4])
    with pytest.raises(TypeError, match="params"):
        Vehicle(params="ardrone")
    with pytest.raises(FloatingPointError, match="not finite|singularity"):
        v = Vehicle(state=_at())
        v.state[3] = 1e308  # the next step overflows
        v.step(np.full(4, 50.0), 0.01)


def test_step_is_rk4_on_the_models_derivatives():
    """Vehicle.step integrates on Python floats; here the same RK4 on numpy arrays of
    visloc.model.derivatives, with commands that change every few steps, a held external
    force, a re-trim and motor lag: the states agree to the last bits."""
    from visloc.model import derivatives
    from visloc.model.propulsion import pwm_bar

    rng = np.random.default_rng(4)
    for lag in (0.0, 0.03):
        v = Vehicle(motor_lag=lag, gyroscopic=True)
        v.trim(np.full(4, 50.0))
        s, bar = v.state.copy(), pwm_bar(np.full(4, 50.0), ARDRONE2.k)
        for k in range(40):
            pwm = rng.uniform(40.0, 60.0, 4)
            force = rng.normal(size=3) if k % 2 else None
            for _ in range(3):
                target = pwm_bar(pwm, ARDRONE2.k)
                bar = target + (bar - target) * np.exp(-0.002 / lag) if lag else target
                u = v.gamma @ bar

                def f(x, u=u, force=force):
                    d = derivatives(x, u, ARDRONE2, gyroscopic=True)
                    if force is not None:
                        d[3:6] += force / ARDRONE2.mass
                    return d

                k1 = f(s)
                k2 = f(s + 0.5 * 0.002 * k1)
                k3 = f(s + 0.5 * 0.002 * k2)
                k4 = f(s + 0.002 * k3)
                s = s + 0.002 / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
                assert np.allclose(v.step(pwm, 0.002, force), s, rtol=1e-12, atol=1e-12)
