"""Pilot-frame linearisation at hover (report §4.1, eqs. 4.1-4.4, Appendix B)."""

import dataclasses

import numpy as np
import pytest

from visloc.control import (
    DEFAULT_ARM,
    INPUT_NAMES,
    PILOT_STATE_NAMES,
    from_pilot,
    hover_input,
    linearize_analytical,
    linearize_numerical,
    mixer_input_matrix,
    pwm_input_matrix,
    resolve_arm,
    to_pilot,
)
from visloc.model import ARDRONE2, STATE_NAMES, derivatives, hover_pwm, inputs_from_pwm

P = ARDRONE2


def test_orderings_follow_the_model_layer():
    assert [n.removesuffix("_P") for n in PILOT_STATE_NAMES] == list(STATE_NAMES)
    assert INPUT_NAMES == ("T", "tau_x", "tau_y", "tau_z")


@pytest.mark.parametrize("psi0", [0.0, 0.7, -2.5, 3.1])
@pytest.mark.parametrize("gyroscopic", [False, True])
def test_numerical_jacobian_matches_the_written_out_matrices(psi0, gyroscopic):
    a_num, b_num = linearize_numerical(P, psi0=psi0, gyroscopic=gyroscopic)
    a, b = linearize_analytical(P)
    np.testing.assert_allclose(a_num, a, atol=1e-7)
    np.testing.assert_allclose(b_num, b, atol=1e-7)


def test_written_out_entries():
    a, b = linearize_analytical(P)
    assert a[3, 7] == pytest.approx(-P.g)  # udot_P = -g theta
    assert a[4, 6] == pytest.approx(P.g)  # vdot_P = g phi
    assert b[5, 0] == pytest.approx(-1 / P.mass)  # wdot_P = -T/m
    np.testing.assert_allclose(np.diag(b[9:12, 1:4]), 1 / np.array([P.Ixx, P.Iyy, P.Izz]))
    assert np.count_nonzero(a) == 8 and np.count_nonzero(b) == 4


def test_hover_is_an_equilibrium_for_any_heading():
    for psi in (0.0, 1.0, -3.0):
        x = np.zeros(12)
        x[8] = psi
        np.testing.assert_allclose(derivatives(x, hover_input(P), P), 0.0, atol=1e-12)


def test_pilot_frame_round_trip_and_heading(rng):
    s = rng.normal(size=12)
    origin = rng.normal(size=3)
    sp = to_pilot(s, 0.8, origin=origin)
    np.testing.assert_allclose(from_pilot(sp, 0.8, origin=origin), s)
    s = np.zeros(12)
    s[0], s[3] = 1.0, 2.0  # 1 m north, 2 m/s north; heading east: north is the pilot's left
    sp = to_pilot(s, np.pi / 2)
    np.testing.assert_allclose(sp[:6], [0.0, -1.0, 0.0, 0.0, -2.0, 0.0], atol=1e-15)


def test_mixer_input_matrices_match_the_propulsion_model():
    arm = resolve_arm(P)
    assert arm == DEFAULT_ARM == 0.125
    _, b = linearize_analytical(P)
    bg = mixer_input_matrix(P)
    # thrust row: each motor's pwm_bar adds c_mean to T
    np.testing.assert_allclose(bg[5], -P.c_mean / P.mass * np.ones(4))
    # B_pwm against a finite difference of the static propulsion model around the trim
    pwm0 = np.full(4, hover_pwm(P))
    bp = pwm_input_matrix(P)
    h = 1e-4
    p_arm = dataclasses.replace(P, arm=arm)
    for i in range(4):
        e = np.zeros(4)
        e[i] = h
        du = (inputs_from_pwm(pwm0 + e, p_arm) - inputs_from_pwm(pwm0 - e, p_arm)) / (2 * h)
        np.testing.assert_allclose(bp[:, i], b @ du, rtol=1e-6, atol=1e-12)


def test_arm_argument_and_params_arm():
    assert resolve_arm(P, 0.2) == 0.2
    assert resolve_arm(dataclasses.replace(P, arm=0.15)) == 0.15
    big = mixer_input_matrix(P, arm=0.2)
    small = mixer_input_matrix(P, arm=0.1)
    np.testing.assert_allclose(big[9:11], 2 * small[9:11])
    with pytest.raises(ValueError, match="arm"):
        resolve_arm(P, -0.1)
    with pytest.raises(TypeError, match="arm"):
        resolve_arm(P, "0.1")


def test_bad_arguments():
    with pytest.raises(TypeError, match="params"):
        linearize_analytical({"mass": 1.0})
    with pytest.raises(ValueError, match="step"):
        linearize_numerical(P, step=0.0)
    with pytest.raises(TypeError, match="psi0"):
        linearize_numerical(P, psi0="north")
    with pytest.raises(ValueError, match="state"):
        to_pilot(np.zeros(11), 0.0)
    with pytest.raises(ValueError, match="origin"):
        from_pilot(np.zeros(12), 0.0, origin=[1.0, 2.0])
