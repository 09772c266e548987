"""Luenberger observer of report eq. 3.14: pole placement (Ackermann) and streaming."""

import math

import numpy as np
import pytest
from scipy.signal import place_poles

from visloc.estimation import LuenbergerObserver, ackermann_observer_gain, luenberger_gains

A = np.array([[0.0, 1.0], [0.0, 0.0]])
C = np.array([[1.0, 0.0]])

POLES = [(-3.0, -3.0), (-2.0, -5.0), (-2.0 + 3.0j, -2.0 - 3.0j), (-0.5, -40.0)]
Z_POLES = [(0.9, 0.9), (0.5, 0.8), (0.6 + 0.3j, 0.6 - 0.3j), (0.0, 0.0)]


def _assert_poles(matrix, poles):
    want = np.poly(np.asarray(poles, complex)).real
    assert np.allclose(np.poly(matrix), want, rtol=0, atol=1e-12)  # exact characteristic poly
    got = np.sort_complex(np.linalg.eigvals(matrix))
    # eigenvalues of a defective matrix are only sqrt(eps)-accurate; distinct ones to 1e-12
    assert np.allclose(got, np.sort_complex(np.asarray(poles, complex)), atol=1e-7)


@pytest.mark.parametrize("poles", POLES)
def test_continuous_pole_placement(poles):
    L = luenberger_gains(poles)
    _assert_poles(A - np.outer(L, C), poles)
    p1, p2 = poles
    assert np.allclose(L, [-(p1 + p2).real, (p1 * p2).real])


def test_place_poles_refuses_repeated_poles_ackermann_does_not():
    with pytest.raises(ValueError):
        place_poles(A.T, C.T, [-3.0, -3.0])
    assert np.allclose(luenberger_gains([-3.0, -3.0]), [6.0, 9.0])
    L = luenberger_gains([-2.0, -5.0])
    assert np.allclose(L, place_poles(A.T, C.T, [-2.0, -5.0]).gain_matrix.ravel())


@pytest.mark.parametrize("poles", Z_POLES)
@pytest.mark.parametrize("dt", [0.01, 0.2])
def test_discrete_pole_placement(poles, dt):
    F = np.array([[1.0, dt], [0.0, 1.0]])  # ZOH = forward Euler for the double integrator
    L = luenberger_gains(poles, discrete_dt=dt)
    _assert_poles(F - np.outer(L, C), poles)
    Lc = luenberger_gains(poles, discrete_dt=dt, form="current")
    _assert_poles(F - np.outer(Lc, C) @ F, poles)


def test_ackermann_general_third_order():
    a = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, -2.0, -3.0]])
    c = np.array([1.0, 0.0, 0.0])
    poles = [-4.0, -4.0, -4.0]
    _assert_poles(a - np.outer(ackermann_observer_gain(a, c, poles), c), poles)


def test_pole_argument_errors():
    with pytest.raises(ValueError, match="conjugate"):
        luenberger_gains([-1.0 + 1.0j, -2.0])
    with pytest.raises(ValueError, match="poles"):
        luenberger_gains([-1.0])
    with pytest.raises(ValueError, match="discrete_dt"):
        luenberger_gains([0.5, 0.5], discrete_dt=0.0)
    with pytest.raises(ValueError, match="form"):
        luenberger_gains([0.5, 0.5], discrete_dt=0.1, form="other")
    with pytest.raises(ValueError, match="observable"):
        ackermann_observer_gain(A, [0.0, 1.0], [-1.0, -2.0])
    with pytest.raises(ValueError, match="negative real"):
        LuenbergerObserver([-1.0, 0.5], 0.01)


def test_observer_error_decays_at_the_requested_rate():
    """Current form with poles exp(p dt): the error after k steps of a constant-velocity truth
    follows the continuous observer's (double pole -3: (1 + 3t) e^{-3t} scaling)."""
    obs = LuenbergerObserver([-3.0, -3.0], 0.01, initial_position=(1.0, -1.0))
    for _ in range(100):  # truth: at rest at the origin
        pos, vel = obs.update((0.0, 0.0))
    assert np.all(np.abs(pos) < 0.25) and np.all(np.abs(pos) > 0.05)
    for _ in range(400):
        pos, vel = obs.update((0.0, 0.0))
    assert np.all(np.abs(pos) < 1e-4) and np.all(np.abs(vel) < 1e-3)


def test_observer_tracks_ramp_with_zero_velocity_error():
    rng = np.random.default_rng(1)
    dt = 1.0 / 30.0
    v = np.array([0.8, -0.3])
    obs = LuenbergerObserver([-2.0 + 1.0j, -2.0 - 1.0j], dt)
    steps = dt * (1.0 + 0.5 * rng.random(600))  # irregular frame intervals
    t = np.cumsum(steps)
    for ti, h in zip(t, steps):
        pos, vel = obs.update(np.array([0.5, 2.0]) + v * ti, h)
    assert np.allclose(vel, v, atol=1e-9), f"steady-state velocity error {vel - v}"
    assert np.allclose(pos, np.array([0.5, 2.0]) + v * t[-1], atol=1e-9)
    assert obs.time == pytest.approx(t[-1])


def test_missing_and_non_finite_measurements_predict_only():
    dt = 0.05
    obs = LuenbergerObserver([-3.0, -3.0], dt)
    assert obs.update(None)[0].tolist() == [0.0, 0.0] and not obs.initialised
    v = np.array([1.0, 0.5])
    for k in range(1, 201):
        obs.update(v * k * dt)
    pos, vel = obs.update(None)  # camera lost the marker: coast at the estimated velocity
    assert np.allclose(pos, v * 201 * dt) and np.allclose(vel, v)
    pos, vel = obs.update([np.nan, 3.0])
    assert obs.skipped == 1 and np.allclose(pos, v * 202 * dt)
    pos, vel = obs.update(v * 203 * dt)
    assert np.allclose(pos, v * 203 * dt) and np.all(np.isfinite(vel))


@pytest.mark.parametrize("dt", [0.0, -0.1, math.nan])
def test_observer_refuses_non_positive_dt(dt):
    obs = LuenbergerObserver([-3.0, -3.0], 0.01)
    with pytest.raises(ValueError, match="dt"):
        obs.update((0.0, 0.0), dt)
    with pytest.raises(ValueError, match="z"):
        obs.update((0.0, 0.0, 0.0))


@pytest.mark.parametrize("poles", [(-3.0, -3.0), (-2 + 1j, -2 - 1j), (-5.0, -0.5)])
@pytest.mark.parametrize("dt", [1e-300, 1e-9, 1e-3, 1 / 30, 2.0, 1e300])
def test_observer_gains_place_the_poles_at_any_step(poles, dt):
    # the streaming observer's current-form gains put eig(F - L C F) at exp(p dt); Ackermann's
    # formula lost them (and raised "not observable") below dt ~ 1e-150 and above 1e150
    obs = LuenbergerObserver(poles, 0.01)
    l1, l2 = obs.gains(dt)
    p = np.asarray(poles, complex)
    assert l1 == pytest.approx(-math.expm1(p.sum().real * dt), rel=1e-12)
    assert l2 == pytest.approx((np.expm1(p[0] * dt) * np.expm1(p[1] * dt)).real / dt, rel=1e-12)
    if 1e-6 < dt < 1e6:  # where the matrix and its eigenvalues are representable
        f = np.array([[1.0, dt], [0.0, 1.0]])
        closed = f - np.outer([l1, l2], np.array([1.0, 0.0]) @ f)
        got = np.sort_complex(np.linalg.eigvals(closed))
        np.testing.assert_allclose(got, np.sort_complex(np.exp(p * dt)), atol=1e-6)
        np.testing.assert_allclose([l1, l2], luenberger_gains(np.exp(p * dt), discrete_dt=dt, form="current"),
                                   rtol=1e-6)
    pos, vel = LuenbergerObserver(poles, dt, initial_position=(0.0, 0.0)).update((1.0, 1.0))
    assert np.all(np.isfinite(pos)) and np.all(np.isfinite(vel)) and np.all(pos > 0)
