"""Streaming controller on the non-linear model (report §4.2, Figure 4.4, §4.4, eq. 4.6)."""

import dataclasses
import math

import numpy as np
import pytest

from visloc.control import Controller, ControlSpecs, LoopSpec, wrap_angle
from visloc.model import (
    ARDRONE2,
    derivatives,
    hover_pwm,
    mixer_matrix,
    pwm_bar,
    pwm_from_bar,
    pwm_from_inputs,
)

P = ARDRONE2
DT = 0.005  # 200 Hz, the AR.Drone's navdata rate


def simulate(ctrl, setpoint, seconds, *, state=None, c=None, d=None):
    """RK4 of the rigid body driven by the motors: ``u = Gamma_true (pwm + k)^2`` held per step."""
    gamma = mixer_matrix(P, c=c, d=d, arm=ctrl.arm)
    x = np.zeros(12) if state is None else np.array(state, float)
    log = []
    for _ in range(round(seconds / DT)):
        cmd = ctrl.pwm(x, setpoint, DT)
        u = gamma @ pwm_bar(cmd.pwm, P.k)

        def f(s, u=u):
            return derivatives(s, u, P)

        k1 = f(x)
        k2 = f(x + 0.5 * DT * k1)
        k3 = f(x + 0.5 * DT * k2)
        k4 = f(x + DT * k3)
        x = x + DT / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        log.append(x)
    return np.array(log)


def test_hover_at_the_setpoint_gives_the_trim():
    ctrl = Controller()
    sp = np.array([1.0, -2.0, -1.5, 0.4])
    x = np.zeros(12)
    x[:3], x[8] = sp[:3], sp[3]
    np.testing.assert_allclose(ctrl.command(x, sp, DT), [P.mass * P.g, 0, 0, 0], atol=1e-12)
    res = ctrl.pwm(x, sp, DT)
    np.testing.assert_allclose(res.pwm, hover_pwm(P), rtol=1e-12)
    assert not res.saturated


def test_motor_commands_are_pwm_from_inputs_of_the_command():
    # the controller keeps Gamma^-1; its commands are pwm_from_inputs' (which solves), saturations too
    rng = np.random.default_rng(3)
    for scale in (0.01, 0.3, 3.0):  # near hover, moderate, far off: every motor clipped one way or the other
        for _ in range(30):
            c = Controller(P)
            state = np.r_[rng.normal(0, scale, 6), rng.normal(0, 0.1 * scale, 6)]
            setpoint = rng.normal(0, scale, 4)
            got = c.pwm(state, setpoint, 0.0)
            want = pwm_from_inputs(Controller(P).command(state, setpoint, 0.0), P, gamma=c.gamma)
            np.testing.assert_allclose(got.pwm, want.pwm, rtol=1e-12, atol=1e-9)
            np.testing.assert_allclose(got.pwm_bar, want.pwm_bar, rtol=1e-12, atol=1e-9)
            assert got.saturated == want.saturated and got.reason.split(":")[0] == want.reason.split(":")[0]
    below = pwm_from_bar(np.array([-1.0, 0.5 * P.k**2, 1600.0, 200.0**2]), P.k)
    assert below.pwm.tolist() == [0.0, 0.0, 40.0 - P.k, 100.0] and below.reason.count("motor") == 3


def test_error_state_is_in_the_pilot_frame():
    ctrl = Controller()
    x = np.zeros(12)
    x[8] = math.pi / 2  # heading east
    x[3] = 1.0  # flying north at 1 m/s
    e = ctrl.error_state(x, [0.0, 1.0, 0.0, -math.pi + 0.1])  # set point 1 m east
    np.testing.assert_allclose(e[:2], [-1.0, 0.0], atol=1e-12)  # it lies straight ahead
    np.testing.assert_allclose(e[3:5], [0.0, -1.0], atol=1e-12)  # north is to the left
    assert e[8] == pytest.approx(wrap_angle(math.pi / 2 + math.pi - 0.1))
    assert abs(e[8]) <= math.pi


def test_side_step_settles():
    ctrl = Controller()
    log = simulate(ctrl, [0.0, 1.0, 0.0, 0.0], 12.0)
    assert abs(log[-1, 1] - 1.0) < 0.02 and np.max(np.abs(log[-1, [0, 2]])) < 0.01
    assert np.max(log[:, 1]) < 1.1  # the integrators do not wind up on the step
    assert np.max(np.abs(log[:, 6])) < 0.35  # the roll needed for 1 m stays modest
    assert np.max(log[:, 2]) > 0  # it sinks a little while rolled (report §4.4, Fig. 4.6)


def test_integrators_running_all_the_time_overshoot():
    sp = [0.0, 1.0, 0.0, 0.0]
    always = simulate(Controller(integral_zone=(1e9, 1e9)), sp, 8.0)
    conditional = simulate(Controller(), sp, 8.0)
    over_always, over_conditional = np.max(always[:, 1]) - 1.0, np.max(conditional[:, 1]) - 1.0
    assert over_always > 0.08  # windup on the step
    assert over_always > 2.0 * max(over_conditional, 0.0)


def test_bounded_torques_limit_the_roll_of_large_steps():
    sp = [0.0, 6.0, 0.0, 0.0]
    bounded = simulate(Controller(max_tilt=0.3), sp, 15.0)
    free = simulate(Controller(max_tilt=math.inf), sp, 15.0)
    roll_bounded = np.max(np.abs(bounded[:, 6]))
    assert roll_bounded < 0.4 < np.max(np.abs(free[:, 6]))
    assert abs(bounded[-1, 1] - 6.0) < 0.05


def test_integral_action_removes_the_motor_spread_offset():
    c = np.array(P.c_quad4)  # the measured motors of quadrotor 4 instead of the mean
    d = np.array(P.d_quad4)
    sp = [0.5, 0.0, -1.0, 0.3]
    start = np.zeros(12)
    start[2] = -1.0
    no_integral = ControlSpecs(position=dataclasses.replace(ControlSpecs().position, integral=0.0),
                               height=LoopSpec(3.0, 60.0), yaw=LoopSpec(3.0, 60.0))
    pd = simulate(Controller(specs=no_integral), sp, 40.0, c=c, d=d, state=start)
    assert abs(pd[-1, 0] - sp[0]) > 0.1 and abs(pd[-1, 8] - sp[3]) > 0.2  # PD alone: offsets
    ctrl = Controller()
    log = simulate(ctrl, sp, 40.0, c=c, d=d, state=start)
    np.testing.assert_allclose(log[-1, [0, 1, 2, 8]], sp, atol=0.02)
    assert np.any(np.abs(ctrl.integral) > 1e-3)
    ctrl.reset()
    assert not np.any(ctrl.integral)


def test_arm_from_params_and_arguments():
    assert Controller().arm == 0.125
    assert Controller(dataclasses.replace(P, arm=0.14)).arm == 0.14
    assert Controller(arm=0.1).gamma[1, 0] == pytest.approx(0.1 * P.c_mean)


def test_bad_arguments():
    ctrl = Controller()
    with pytest.raises(ValueError, match="state"):
        ctrl.command(np.zeros(9), np.zeros(4), DT)
    with pytest.raises(ValueError, match="setpoint"):
        ctrl.command(np.zeros(12), np.zeros(3), DT)
    with pytest.raises(ValueError, match="dt"):
        ctrl.command(np.zeros(12), np.zeros(4), -0.01)
    with pytest.raises(ValueError, match="state"):
        ctrl.command(np.full(12, np.nan), np.zeros(4), DT)
    with pytest.raises(ValueError, match="max_tilt"):
        Controller(max_tilt=0.0)
    with pytest.raises(TypeError, match="gains"):
        Controller(gains={"roll": 1.0})


def test_wrap_angle_never_returns_pi():
    # (a + pi) % 2 pi rounds to 2 pi just below -pi: the result was +pi, outside [-pi, pi)
    from visloc.estimation._fused import wrap_angle as wrap_scalar

    below = np.nextafter(-math.pi, -np.inf)
    for f in (wrap_angle, wrap_scalar):
        assert f(below) == -math.pi and f(math.pi) == -math.pi and f(0.25) == 0.25
    out = wrap_angle(np.array([below, 7.0, -0.5]))
    assert out[0] == -math.pi and out[1] == pytest.approx(7.0 - 2 * math.pi) and out[2] == -0.5


def test_the_compiled_feedback_law_is_the_python_one():
    """Controller(native=True) and native=False command the same motors and integrate the
    same errors, step after step, near the set point and far off it (every bound active in
    turn, integrators held and running): bit for bit where Python's sum() is plain (3.11),
    to the last bits where it is compensated (3.12 on)."""
    import sys

    exact = sys.version_info < (3, 12)
    rng = np.random.default_rng(11)
    saturated = 0
    for scale in (0.01, 0.3, 3.0):
        fast, plain = Controller(native=True), Controller(native=False)
        sp = np.array([0.5, -0.3, -1.0, 0.2])
        for _ in range(60):
            x = np.r_[sp[:3] + rng.normal(0, scale, 3), rng.normal(0, scale, 3), rng.normal(0, 0.2 * scale, 3),
                      rng.normal(0, scale, 3)]
            a, b = fast.pwm(x, sp, DT), plain.pwm(x, sp, DT)
            if exact:
                assert a.pwm.tolist() == b.pwm.tolist() and fast.integral.tolist() == plain.integral.tolist()
            else:
                np.testing.assert_allclose(a.pwm, b.pwm, rtol=1e-12, atol=1e-12)
                np.testing.assert_allclose(fast.integral, plain.integral, rtol=1e-12, atol=1e-15)
            assert a.saturated == b.saturated and a.reason == b.reason
            saturated += a.saturated
        assert np.any(fast.integral != 0.0)
    assert 0 < saturated < 180  # both ways: commands within reach and clipped ones


def test_native_must_be_a_bool_or_none():
    with pytest.raises(TypeError, match="native"):
        Controller(native="yes")
