"""Propulsion model (eqs. 2.15-2.18), mixer (2.12), its inverse (4.6) and the hover trim."""

import dataclasses
import math

import numpy as np
import pytest

from visloc.model import (
    ARDRONE2,
    MOTOR_LAYOUT,
    YAW_SIGNS,
    hover_pwm,
    inputs_from_pwm,
    mixer_matrix,
    pwm_bar,
    pwm_from_inputs,
    thrust,
    torque,
)

ARM = 0.13  # an arm distance for the tests only: the report prints none
P = dataclasses.replace(ARDRONE2, arm=ARM)


def test_thrust_and_torque_follow_eqs_2_15_to_2_18():
    pwm = np.array([-5.0, 0.0, 1e-9, 50.0, 100.0])
    c, d, k = 0.1318e-3, 0.8722e-5, 25.19
    expected = np.where(pwm > 0, (pwm + k) ** 2, 0.0)
    np.testing.assert_allclose(thrust(pwm, c, k), c * expected)
    np.testing.assert_allclose(torque(pwm, d, k), d * expected)
    assert thrust(0.0, c, k) == 0.0 and thrust(1e-9, c, k) > 0.0  # jump at 0 (eq. 2.17)
    # per-motor coefficients broadcast
    np.testing.assert_allclose(thrust([50.0] * 4, ARDRONE2.c_quad3, k),
                               np.array(ARDRONE2.c_quad3) * 75.19**2)


def test_mixer_is_eq_2_12_as_printed():
    c = np.array(ARDRONE2.c_quad4)
    d = np.array(ARDRONE2.d_quad4)
    dd = ARM
    printed = np.array([  # report eq. (2.12), transcribed
        [c[0], c[1], c[2], c[3]],
        [dd * c[0], -dd * c[1], -dd * c[2], dd * c[3]],
        [dd * c[0], dd * c[1], -dd * c[2], -dd * c[3]],
        [-d[0], d[1], -d[2], d[3]],
    ])
    np.testing.assert_allclose(mixer_matrix(ARDRONE2, c=c, d=d, arm=ARM), printed, rtol=1e-15)
    np.testing.assert_allclose(mixer_matrix(P, c=c, d=d), printed, rtol=1e-15)


def test_mixer_matches_forces_at_the_motor_layout():
    """Torque rows = r_i x (-T_i e3) with motor 1 front-left, 2 front-right, ... (NED body)."""
    gamma = mixer_matrix(P)
    for i in range(4):
        r = np.array([*MOTOR_LAYOUT[i] * ARM, 0.0])
        force = np.array([0.0, 0.0, -ARDRONE2.c_mean])  # thrust per unit pwm_bar, along -z
        moment = np.cross(r, force)
        np.testing.assert_allclose(gamma[1:3, i], moment[:2], rtol=1e-15)
        assert gamma[0, i] == ARDRONE2.c_mean
        assert gamma[3, i] == YAW_SIGNS[i] * ARDRONE2.d_mean  # (-1)^i, eq. (2.10)
    np.testing.assert_array_equal(YAW_SIGNS, [(-1) ** i for i in range(1, 5)])


def test_mixer_needs_an_arm_distance():
    with pytest.raises(ValueError, match="arm"):
        mixer_matrix(ARDRONE2)
    with pytest.raises(ValueError, match="arm"):
        mixer_matrix(ARDRONE2, arm=-1.0)
    with pytest.raises(ValueError, match="c"):
        mixer_matrix(P, c=[1.0, 2.0])
    with pytest.raises(TypeError, match="params"):
        mixer_matrix({"arm": 0.1})


def test_round_trip_pwm_to_inputs_and_back(rng):
    for _ in range(50):
        pwm = rng.uniform(1.0, 100.0, 4)
        u = inputs_from_pwm(pwm, P)
        res = pwm_from_inputs(u, P)
        assert not res.saturated, res.reason
        assert res.reason == ""
        np.testing.assert_allclose(res.pwm, pwm, atol=1e-9)
        np.testing.assert_allclose(res.pwm_bar, pwm_bar(pwm, P.k), rtol=1e-10)


def test_hover_inputs_give_the_hover_trim():
    u = np.array([P.mass * P.g, 0.0, 0.0, 0.0])
    res = pwm_from_inputs(u, P)
    assert not res.saturated
    np.testing.assert_allclose(res.pwm, hover_pwm(P), atol=1e-9)


def test_unreachable_inputs_are_flagged():
    t0 = P.mass * P.g
    # a roll torque needing negative thrust on motors 2 and 3
    res = pwm_from_inputs([t0 * 0.1, 0.5, 0.0, 0.0], P)
    assert res.saturated
    assert np.all(res.pwm >= 0) and np.all(res.pwm <= 100)
    assert "motor 2" in res.reason and "unreachable" in res.reason
    assert res.pwm_bar[1] < 0 and res.pwm[1] == 0.0
    # too much thrust: every motor clipped at 100 %
    res = pwm_from_inputs([20.0, 0.0, 0.0, 0.0], P)
    assert res.saturated and np.all(res.pwm == 100.0) and "clipped" in res.reason
    # less thrust than the smallest positive command gives: cut to 0
    res = pwm_from_inputs([4 * P.c_mean * P.k**2 * 0.5, 0.0, 0.0, 0.0], P)
    assert res.saturated and np.all(res.pwm == 0.0) and "minimum" in res.reason


def test_pwm_from_inputs_checks_arguments():
    with pytest.raises(ValueError, match="u"):
        pwm_from_inputs([1.0, 0.0, 0.0], P)
    with pytest.raises(ValueError, match="gamma"):
        pwm_from_inputs([1.0, 0.0, 0.0, 0.0], P, gamma=np.eye(3))
    with pytest.raises(ValueError, match="gamma"):
        pwm_from_inputs([1.0, 0.0, 0.0, 0.0], P, gamma=np.zeros((4, 4)))
    with pytest.raises(ValueError, match="pwm_max"):
        pwm_from_inputs([1.0, 0.0, 0.0, 0.0], P, pwm_max=-1.0)
    with pytest.raises(TypeError, match="u"):
        pwm_from_inputs(["a", "b", "c", "d"], P)


def test_hover_pwm_is_about_66_9_percent():
    m, g, c_bar, k = 0.456, 9.81, 0.1318e-3, 25.19
    by_hand = math.sqrt(m * g / (4 * c_bar)) - k  # T0 = m g (section 4.1), eq. (2.15)
    h = hover_pwm(ARDRONE2)
    assert abs(h - by_hand) < 1e-9, f"hover pwm = {h!r} %, by hand {by_hand!r} %"
    # 66.9 % is the figure (the report itself prints no hover command)
    assert round(h, 1) == 66.9, f"hover pwm = {h:.6f} % for m = {m} kg"
    assert hover_pwm(ARDRONE2, mass=0.502) > h
    with pytest.raises(ValueError, match="mass"):
        hover_pwm(ARDRONE2, mass=0.0)


def test_a_bool_pwm_max_is_refused():
    # True passed the numbers.Real check and gave a boolean pwm array
    u = np.array([P.mass * P.g, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="pwm_max"):
        pwm_from_inputs(u, P, pwm_max=True)
