"""Rigid-body equations (report eqs. 2.1-2.8 / A.1-A.16), NED, Z-Y-X Euler angles."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation

from visloc.model import (
    ARDRONE2,
    STATE_NAMES,
    derivatives,
    euler_rate_matrix,
    motor_lag_derivative,
    pwm_bar,
    rotation_matrix,
)

M, G = ARDRONE2.mass, ARDRONE2.g
HOVER = np.array([M * G, 0.0, 0.0, 0.0])


def skew(w):
    return np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])


def random_state(rng):
    s = rng.normal(size=12)
    s[6:9] = rng.uniform(-1.0, 1.0, 3)  # |theta| < 1 rad: away from gimbal lock
    return s


def test_state_layout():
    assert STATE_NAMES == ("x", "y", "z", "u", "v", "w", "phi", "theta", "psi", "p", "q", "r")


def test_rotation_matrix_is_zyx(rng):
    for _ in range(20):
        phi, theta, psi = rng.uniform(-3, 3, 3)
        R = rotation_matrix([phi, theta, psi])
        expected = Rotation.from_euler("ZYX", [psi, theta, phi]).as_matrix()
        np.testing.assert_allclose(R, expected, atol=1e-14)
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-14)


def test_euler_rates_by_finite_differences(rng):
    """lambda' = Q(lambda) omega must make R(lambda)' = R [omega]x (body rates)."""
    h = 1e-6
    for _ in range(20):
        lam = rng.uniform(-1.2, 1.2, 3)
        omega = rng.normal(size=3)
        lam_dot = euler_rate_matrix(lam) @ omega
        r_dot = (rotation_matrix(lam + h * lam_dot) - rotation_matrix(lam - h * lam_dot)) / (2 * h)
        np.testing.assert_allclose(r_dot, rotation_matrix(lam) @ skew(omega), atol=1e-8)


def test_kinematic_rows_by_finite_differences(rng):
    """Position and attitude rows of derivatives() against a numerical time derivative of
    a trajectory integrated with them (consistency of (A.5)-(A.10))."""
    s0 = random_state(rng)
    u = np.array([M * G * 1.1, 0.01, -0.02, 0.005])
    sol = solve_ivp(lambda t, s: derivatives(s, u, ARDRONE2), (0, 0.02), s0,
                    dense_output=True, rtol=1e-11, atol=1e-12)
    h, t = 1e-4, 0.01
    numeric = (sol.sol(t + h) - sol.sol(t - h)) / (2 * h)
    np.testing.assert_allclose(numeric, derivatives(sol.sol(t), u, ARDRONE2), atol=1e-5)


@pytest.mark.parametrize("psi", [0.0, 0.7, -2.5])
def test_hover_is_an_equilibrium(psi):
    s = np.zeros(12)
    s[8] = psi
    np.testing.assert_allclose(derivatives(s, HOVER, ARDRONE2), 0.0, atol=1e-12)
    np.testing.assert_allclose(derivatives(s, HOVER, ARDRONE2, gyroscopic=True), 0.0, atol=1e-12)
    s[3:6] = [1.0, -2.0, 0.5]  # steady flight: only the position moves
    np.testing.assert_allclose(derivatives(s, HOVER, ARDRONE2), [1, -2, 0.5] + [0] * 9,
                               atol=1e-12)


def test_free_fall(rng):
    for _ in range(5):
        s = random_state(rng)
        d = derivatives(s, np.zeros(4), ARDRONE2)
        np.testing.assert_allclose(d[3:6], [0.0, 0.0, G])  # NED: falls toward +z
        np.testing.assert_allclose(d[0:3], s[3:6])
        np.testing.assert_allclose(d[9:12], 0.0)


def test_pure_yaw_torque_spins_about_z():
    tau_z = 1e-3
    u = np.array([M * G, 0.0, 0.0, tau_z])
    d = derivatives(np.zeros(12), u, ARDRONE2)
    expected = np.zeros(12)
    expected[11] = tau_z / ARDRONE2.Izz
    np.testing.assert_allclose(d, expected, atol=1e-15)
    sol = solve_ivp(lambda t, s: derivatives(s, u, ARDRONE2), (0, 1.0), np.zeros(12),
                    rtol=1e-10, atol=1e-12)
    end = sol.y[:, -1]
    assert end[8] == pytest.approx(0.5 * tau_z / ARDRONE2.Izz, rel=1e-8)  # psi = a t^2 / 2
    assert end[11] == pytest.approx(tau_z / ARDRONE2.Izz, rel=1e-8)
    np.testing.assert_allclose(end[[0, 1, 2, 3, 4, 5, 6, 7, 9, 10]], 0.0, atol=1e-12)


def test_thrust_tilted_forward_accelerates_forward():
    s = np.zeros(12)
    s[7] = -0.1  # nose down (negative pitch in NED)
    d = derivatives(s, HOVER, ARDRONE2)
    assert d[3] == pytest.approx(G * np.sin(0.1))
    s = np.zeros(12)
    s[6] = 0.1  # right roll
    assert derivatives(s, HOVER, ARDRONE2)[4] == pytest.approx(G * np.sin(0.1))  # v' = g phi


def test_linearisation_matches_section_4_1():
    """Jacobian at hover: u' = -g theta, v' = g phi, w' = -T/m, omega' = tau / I."""
    h = 1e-6
    s0 = np.zeros(12)
    A = np.empty((12, 12))
    B = np.empty((12, 4))
    for i in range(12):
        e = np.zeros(12)
        e[i] = h
        up, down = derivatives(s0 + e, HOVER, ARDRONE2), derivatives(s0 - e, HOVER, ARDRONE2)
        A[:, i] = (up - down) / (2 * h)
    for i in range(4):
        e = np.zeros(4)
        e[i] = h
        up, down = derivatives(s0, HOVER + e, ARDRONE2), derivatives(s0, HOVER - e, ARDRONE2)
        B[:, i] = (up - down) / (2 * h)
    A_ref = np.zeros((12, 12))
    A_ref[0:3, 3:6] = np.eye(3)
    A_ref[6:9, 9:12] = np.eye(3)
    A_ref[3, 7] = -G
    A_ref[4, 6] = G
    B_ref = np.zeros((12, 4))
    B_ref[5, 0] = -1 / M
    B_ref[9:12, 1:4] = np.diag(1 / np.diag(ARDRONE2.J))
    np.testing.assert_allclose(A, A_ref, atol=1e-7)
    np.testing.assert_allclose(B, B_ref, rtol=1e-7, atol=1e-7)


@pytest.mark.parametrize("gyroscopic", [False, True])
def test_energy_rates(rng, gyroscopic):
    """d/dt(m |v|^2 / 2 - m g z) = thrust power; d/dt(omega' J omega / 2) = omega . tau."""
    for _ in range(10):
        s = random_state(rng)
        u = np.concatenate([[abs(rng.normal()) * M * G], rng.normal(size=3) * 1e-2])
        d = derivatives(s, u, ARDRONE2, gyroscopic=gyroscopic)
        v, omega = s[3:6], s[9:12]
        e_trans = M * v @ d[3:6] - M * G * d[2]
        thrust_power = -u[0] * v @ rotation_matrix(s[6:9]) @ [0, 0, 1]
        assert e_trans == pytest.approx(thrust_power, rel=1e-10, abs=1e-12)
        e_rot = omega @ ARDRONE2.J @ d[9:12]
        assert e_rot == pytest.approx(omega @ u[1:], rel=1e-10, abs=1e-14)


def test_gyroscopic_term_conserves_angular_momentum():
    """Torque-free tumbling: R J omega (world frame) is constant only with the gyroscopic
    term of Euler's equation, J omega' = -omega x J omega."""
    s0 = np.zeros(12)
    s0[9:12] = [0.3, 0.2, 3.0]

    def world_momentum(s):
        return rotation_matrix(s[6:9]) @ ARDRONE2.J @ s[9:12]

    out = {}
    for gyro in (True, False):
        sol = solve_ivp(lambda t, s, g=gyro: derivatives(s, np.zeros(4), ARDRONE2, gyroscopic=g),
                        (0, 1.0), s0, rtol=1e-11, atol=1e-12)
        assert np.all(np.abs(sol.y[7]) < 1.0)
        out[gyro] = world_momentum(sol.y[:, -1])
    h0 = world_momentum(s0)
    np.testing.assert_allclose(out[True], h0, atol=1e-9)
    assert np.linalg.norm(out[False] - h0) > 1e-4


def test_motor_lag():
    cmd = pwm_bar(np.full(4, 60.0), ARDRONE2.k)
    np.testing.assert_allclose(motor_lag_derivative(cmd, cmd, 0.05), 0.0)
    tau_c = 0.05
    sol = solve_ivp(lambda t, x: motor_lag_derivative(x, cmd, tau_c), (0, tau_c), np.zeros(4),
                    rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(sol.y[:, -1], cmd * (1 - np.exp(-1)), rtol=1e-7)
    with pytest.raises(ValueError, match="tau_c"):
        motor_lag_derivative(cmd, cmd, 0.0)
    with pytest.raises(ValueError, match="pwm_bar_cmd"):
        motor_lag_derivative(cmd, cmd[:3], 0.1)


def test_bad_input_is_rejected():
    with pytest.raises(ValueError, match="state"):
        derivatives(np.zeros(11), HOVER, ARDRONE2)
    with pytest.raises(ValueError, match="u"):
        derivatives(np.zeros(12), [1.0, 2.0], ARDRONE2)
    with pytest.raises(ValueError, match="state"):
        derivatives(np.full(12, np.nan), HOVER, ARDRONE2)
    with pytest.raises(TypeError, match="params"):
        derivatives(np.zeros(12), HOVER, {"mass": 1.0})
    with pytest.raises(TypeError, match="gyroscopic"):
        derivatives(np.zeros(12), HOVER, ARDRONE2, gyroscopic=1)
    s = np.zeros(12)
    s[7] = np.pi / 2
    with pytest.raises(ValueError, match="theta"):
        derivatives(s, HOVER, ARDRONE2)


def test_float_helpers_agree_with_the_array_forms():
    """The sim loop's float helpers give what the checked array functions give."""
    from visloc.model.propulsion import pwm_bar_values
    from visloc.model.rigid_body import euler_rate_values

    rng = np.random.default_rng(3)
    for _ in range(50):
        lam = rng.uniform(-1.0, 1.0, 3)
        omega = rng.normal(size=3)
        np.testing.assert_allclose(euler_rate_values(lam.tolist(), omega.tolist()),
                                   euler_rate_matrix(lam) @ omega, rtol=1e-12, atol=1e-12)
        pwm = rng.uniform(-20.0, 100.0, 4)
        np.testing.assert_allclose(pwm_bar_values(pwm.tolist(), 25.19), pwm_bar(pwm, 25.19), rtol=0, atol=0)


@pytest.mark.parametrize("gyroscopic", [False, True])
def test_the_compiled_derivative_and_rk4_step_are_the_python_ones(gyroscopic):
    """visloc.model._rigid gives the Python version's floats bit for bit: the derivative and
    one RK4 step, with and without an external force, over random states and inputs."""
    from visloc.model.rigid_body import rhs_values, rk4_values

    rng = np.random.default_rng(5)
    inertia = [ARDRONE2.Ixx, ARDRONE2.Iyy, ARDRONE2.Izz]
    for i in range(300):
        s = np.r_[rng.normal(0, 2, 6), rng.uniform(-1.5, 1.5, 3), rng.normal(0, 3, 3)].tolist()
        u = np.r_[rng.uniform(0, 10), rng.normal(0, 0.1, 3)].tolist()
        force = None if i % 2 else rng.normal(0, 0.5, 3).tolist()
        h = float(rng.uniform(1e-4, 0.02))
        kw = {"gyroscopic": gyroscopic, "force": force}
        assert rhs_values(s, u, ARDRONE2.mass, ARDRONE2.g, inertia, native=True, **kw) == \
            rhs_values(s, u, ARDRONE2.mass, ARDRONE2.g, inertia, native=False, **kw)
        assert rk4_values(s, u, h, ARDRONE2.mass, ARDRONE2.g, inertia, native=True, **kw) == \
            rk4_values(s, u, h, ARDRONE2.mass, ARDRONE2.g, inertia, native=False, **kw)


def test_the_compiled_step_on_bad_values():
    """A state gone bad gives non-finite floats compiled (the Python version raises inside
    math, the vehicle reports either as a divergence); wrong sizes raise."""
    from visloc.model.rigid_body import rk4_values

    inertia = [ARDRONE2.Ixx, ARDRONE2.Iyy, ARDRONE2.Izz]
    s = [0.0] * 12
    s[6] = math.inf
    out = rk4_values(s, [1.0, 0, 0, 0], 0.01, ARDRONE2.mass, ARDRONE2.g, inertia, native=True)
    assert not all(map(math.isfinite, out))
    with pytest.raises(ValueError, match="s: expected 12"):
        rk4_values([0.0] * 11, [1.0, 0, 0, 0], 0.01, ARDRONE2.mass, ARDRONE2.g, inertia, native=True)
    with pytest.raises(ValueError, match="force: expected 3"):
        rk4_values([0.0] * 12, [1.0, 0, 0, 0], 0.01, ARDRONE2.mass, ARDRONE2.g, inertia, force=[1.0], native=True)
    with pytest.raises(TypeError):
        rk4_values([0.0] * 12, ["a", 0, 0, 0], 0.01, ARDRONE2.mass, ARDRONE2.g, inertia, native=True)
