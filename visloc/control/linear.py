"""Linearisation at hover in the pilot frame (report section 4.1, eqs. 4.1-4.4, Appendix B).

Pilot frame P (report Figure 4.1, eq. 4.1): the inertial NED frame A turned by the heading
``psi`` about its z axis, so that its x axis points where the quadrotor heads; positions and
velocities are expressed in it with ``xi_P = R_psi^T (xi_A - origin)`` and
``nu_P = R_psi^T nu_A`` (eq. 4.1 with eq. 4.2). Roll and pitch are then the body's attitude
relative to P, and the linear dynamics no longer depend on the heading.

State ordering (12,), the model layer's (:data:`visloc.model.STATE_NAMES`) in pilot axes::

    0-2   x_P, y_P, z_P     position in P, m (z down)
    3-5   u_P, v_P, w_P     velocity in P, m/s
    6-8   phi, theta, psi   roll, pitch (relative to P) and heading, rad
    9-11  p, q, r           body angular velocity, rad/s (report omega_x, omega_y, omega_z)

Input ``u = [T, tau_x, tau_y, tau_z]`` (N, N m): total thrust and body torques, as deviations
from the hover trim ``u0 = [m g, 0, 0, 0]`` (report section 4.1: ``T0 = m g``). Appendix B of
the report is empty in the available text; :func:`linearize_analytical` writes out the
matrices from the linear equations of section 4.1 instead.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from visloc.control._checks import as_array, check_params, check_real, resolve_arm
from visloc.model.params import ARDrone2Params
from visloc.model.propulsion import hover_pwm, mixer_matrix
from visloc.model.rigid_body import derivatives
from visloc.types import FloatArray

PILOT_STATE_NAMES: tuple[str, ...] = (
    "x_P", "y_P", "z_P", "u_P", "v_P", "w_P", "phi", "theta", "psi", "p", "q", "r",
)
"""Names of the 12 pilot-frame states, in order (see the module docstring)."""

INPUT_NAMES: tuple[str, ...] = ("T", "tau_x", "tau_y", "tau_z")
"""Names of the 4 inputs: thrust (N) and body torques (N m)."""


def yaw_rotation(psi: float) -> FloatArray:
    """``R_psi``, the rotation about z by the heading ``psi`` (report eq. 4.2).

    Parameters
    ----------
    psi : float
        Heading, rad.

    Returns
    -------
    ndarray (3, 3)
        ``R_psi``: maps pilot-frame vectors into the inertial frame A, ``v_A = R_psi v_P``.
    """
    c, s = math.cos(psi), math.sin(psi)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])  # report eq. (4.2)


def to_pilot(state: ArrayLike, psi: float, *, origin: ArrayLike | None = None) -> FloatArray:
    """Express a model state (12,) in the pilot frame of heading ``psi`` (report eq. 4.1).

    Parameters
    ----------
    state : array_like (12,)
        Model state in A: ``[x, y, z, u, v, w, phi, theta, psi, p, q, r]`` (m, m/s, rad, rad/s).
    psi : float
        Heading of the pilot frame, rad.
    origin : array_like (3,), optional
        Point of A taken as the pilot frame's origin, m (default: A's origin).

    Returns
    -------
    ndarray (12,)
        ``[R^T (xi - origin), R^T nu, phi, theta, psi, p, q, r]`` with ``R = R_psi``: position
        (m) and velocity (m/s) in pilot axes, the angles and rates unchanged.

    Raises
    ------
    TypeError
        ``psi`` not a real number, or ``state`` / ``origin`` not real numbers.
    ValueError
        ``psi`` not finite; ``state`` not (12,) or ``origin`` not (3,), or a NaN or infinite
        entry in them.
    """
    heading = check_real(psi, "psi")
    s = as_array(state, "state", (12,))
    o = None if origin is None else as_array(origin, "origin", (3,)).tolist()
    return np.array(_pilot_values(s.tolist(), heading, o))


def _pilot_values(state: list[float], psi: float, origin: list[float] | None = None) -> list[float]:
    """:func:`to_pilot` on Python floats, without its argument checks (12 floats ``state``, a
    float ``psi``, 3 floats ``origin`` or None): the controller's every step, where floats
    are several times faster than small arrays; a new list."""
    c, s = math.cos(psi), math.sin(psi)
    ox, oy, oz = (0.0, 0.0, 0.0) if origin is None else origin
    dx, dy = state[0] - ox, state[1] - oy  # report eq. (4.1): xi_P = R_psi^T (xi_A - o)
    return [c * dx + s * dy, -s * dx + c * dy, state[2] - oz,
            c * state[3] + s * state[4], -s * state[3] + c * state[4], state[5], *state[6:]]


def from_pilot(state_p: ArrayLike, psi: float, *, origin: ArrayLike | None = None) -> FloatArray:
    """Inverse of :func:`to_pilot`: a pilot-frame state back into the inertial frame A.

    Parameters
    ----------
    state_p : array_like (12,)
        Pilot-frame state ``[x_P, y_P, z_P, u_P, v_P, w_P, phi, theta, psi, p, q, r]`` (m, m/s,
        rad, rad/s; :data:`PILOT_STATE_NAMES`).
    psi : float
        Heading of the pilot frame, rad.
    origin : array_like (3,), optional
        Point of A that is the pilot frame's origin, m (default: A's origin).

    Returns
    -------
    ndarray (12,)
        ``[R xi_P + origin, R nu_P, phi, theta, psi, p, q, r]`` with ``R = R_psi``: the model
        state in A (:data:`visloc.model.STATE_NAMES`).

    Raises
    ------
    TypeError, ValueError
        As for :func:`to_pilot`.
    """
    r = yaw_rotation(check_real(psi, "psi"))
    out = as_array(state_p, "state_p", (12,)).copy()
    offset = np.zeros(3) if origin is None else as_array(origin, "origin", (3,))
    out[0:3] = r @ out[0:3] + offset
    out[3:6] = r @ out[3:6]
    return out


def hover_input(params: ARDrone2Params) -> FloatArray:
    """Hover trim ``u0 = [m g, 0, 0, 0]`` (report section 4.1: ``T0 = m g``).

    Parameters
    ----------
    params : ARDrone2Params
        Vehicle parameters (mass, g).

    Returns
    -------
    ndarray (4,)
        ``[T, tau_x, tau_y, tau_z]``: thrust in N, torques in N m.

    Raises
    ------
    TypeError
        ``params`` is not an :class:`ARDrone2Params`.
    """
    p = check_params(params)
    return np.array([p.mass * p.g, 0.0, 0.0, 0.0])  # report section 4.1: T0 = m g


def linearize_numerical(
    params: ARDrone2Params,
    *,
    psi0: float = 0.0,
    roll: float = 0.0,
    step: float = 1e-6,
    gyroscopic: bool = False,
) -> tuple[FloatArray, FloatArray]:
    """Jacobians ``(A, B)`` of the non-linear model at hover, in the pilot frame (eqs. 4.3-4.4),
    or in a steady sideways acceleration at a roll angle.

    Central differences of :func:`visloc.model.derivatives` with the state mapped into and out
    of the pilot frame of the (frozen) hover heading ``psi0``.

    Parameters
    ----------
    params : ARDrone2Params
        Vehicle parameters (mass, inertia, g).
    psi0 : float
        Heading at which to linearise, rad; the result does not depend on it (that is the
        point of the pilot frame).
    roll : float
        Roll angle of the operating point, rad (|roll| < 1.2): the attitude in which the
        drone accelerates sideways at ``g tan(roll)`` holding its height, with the thrust
        ``m g / cos(roll)`` (a trajectory's tilt, :func:`visloc.control.trajectory.model_limits`);
        0: hover.
    step : float
        Finite-difference step, in the units of each state / input entry (> 0).
    gyroscopic : bool
        Passed to :func:`visloc.model.derivatives`; the term vanishes at hover anyway.

    Returns
    -------
    A : ndarray (12, 12)
        ``d xdot_P / d x_P`` (state order :data:`PILOT_STATE_NAMES`), 1/s or per-unit rates.
    B : ndarray (12, 4)
        ``d xdot_P / d u`` (input order :data:`INPUT_NAMES`).

    Raises
    ------
    TypeError
        ``params`` is not an :class:`ARDrone2Params`; ``psi0`` or ``step`` not a real number.
    ValueError
        ``psi0`` not finite, or ``step`` not finite and > 0.
    """
    p = check_params(params)
    psi0 = check_real(psi0, "psi0")
    phi0 = check_real(roll, "roll")
    if abs(phi0) >= 1.2:
        raise ValueError(f"roll must be below 1.2 rad (69 degrees) in size, got {phi0}")
    h = check_real(step, "step", positive=True)
    x0 = np.zeros(12)
    x0[6], x0[8] = phi0, psi0
    u0 = hover_input(p)
    u0[0] /= math.cos(phi0)  # the height held: T cos(roll) = m g

    def f(xp: FloatArray, u: FloatArray) -> FloatArray:
        xa = from_pilot(xp, psi0)
        return to_pilot(derivatives(xa, u, p, gyroscopic=gyroscopic), psi0)

    eye_x, eye_u = np.eye(12), np.eye(4)
    a = np.column_stack([(f(x0 + h * e, u0) - f(x0 - h * e, u0)) / (2 * h) for e in eye_x])
    b = np.column_stack([(f(x0, u0 + h * e) - f(x0, u0 - h * e)) / (2 * h) for e in eye_u])
    return a, b


def linearize_analytical(params: ARDrone2Params) -> tuple[FloatArray, FloatArray]:
    """The written-out linear matrices ``(A, B)`` at hover in the pilot frame (report 4.1, App. B).

    From the linear equations of section 4.1::

        xdot_P = u_P   phidot = p    udot_P = -(T0/m) theta = -g theta   pdot = tau_x / Ixx
        ydot_P = v_P   thetadot = q  vdot_P =  (T0/m) phi   =  g phi     qdot = tau_y / Iyy
        zdot_P = w_P   psidot = r    wdot_P = -T / m                     rdot = tau_z / Izz

    Parameters
    ----------
    params : ARDrone2Params
        Vehicle parameters (``mass`` kg, ``g`` m/s^2, ``Ixx, Iyy, Izz`` kg m^2).

    Returns
    -------
    A : ndarray (12, 12)
        ``d xdot_P / d x_P`` in state order :data:`PILOT_STATE_NAMES`: ones for the
        kinematics, ``-g`` from ``theta`` to ``udot_P`` and ``+g`` from ``phi`` to ``vdot_P``
        (m/s^2 per rad).
    B : ndarray (12, 4)
        ``d xdot_P / d u`` in input order :data:`INPUT_NAMES`: ``-1/m`` (1/kg) from the thrust
        to ``wdot_P``, ``1/Ixx, 1/Iyy, 1/Izz`` (1/(kg m^2)) from the torques to the rates.

    Raises
    ------
    TypeError
        ``params`` is not an :class:`ARDrone2Params`.
    """
    p = check_params(params)
    t0 = p.mass * p.g  # report section 4.1: T0 = m g
    a = np.zeros((12, 12))
    a[0:3, 3:6] = np.eye(3)  # xdot_P = u_P, ydot_P = v_P, zdot_P = w_P
    a[3, 7] = -t0 / p.mass  # udot_P = -(T0/m) theta
    a[4, 6] = t0 / p.mass  # vdot_P = (T0/m) phi
    a[6:9, 9:12] = np.eye(3)  # phidot = omega_x, thetadot = omega_y, psidot = omega_z
    b = np.zeros((12, 4))
    b[5, 0] = -1.0 / p.mass  # wdot_P = -T/m
    b[9, 1] = 1.0 / p.Ixx  # omegadot_x = tau_x / Ix
    b[10, 2] = 1.0 / p.Iyy  # omegadot_y = tau_y / Iy
    b[11, 3] = 1.0 / p.Izz  # omegadot_z = tau_z / Iz
    return a, b


def mixer_input_matrix(
    params: ARDrone2Params,
    *,
    arm: float | None = None,
    c: FloatArray | None = None,
    d: FloatArray | None = None,
) -> FloatArray:
    """``B Gamma`` (12, 4): the linear model driven by the squared commands ``pwm_bar`` (eq. 4.3).

    The report's eq. (4.3) uses the mixer of eq. (2.12) as input map: ``u = Gamma pwm_bar`` is
    linear in ``pwm_bar_i = (pwm_i + k)^2``, so deviations of ``pwm_bar`` from its hover value
    enter as ``B Gamma delta_pwm_bar``.

    Parameters
    ----------
    params : ARDrone2Params
        Vehicle parameters.
    arm : float, optional
        Arm distance ``d`` of eq. (2.12), m (see :func:`visloc.control.resolve_arm`).
    c, d : ndarray (4,), optional
        Thrust (N/%^2) and torque (N m/%^2) coefficients of motors 1-4; default the means.

    Returns
    -------
    ndarray (12, 4)
        ``d xdot_P / d pwm_bar`` of motors 1-4, state order :data:`PILOT_STATE_NAMES`: per
        unit of ``pwm_bar`` (%^2).

    Raises
    ------
    TypeError
        ``params`` is not an :class:`ARDrone2Params`; ``arm``, ``c`` or ``d`` not real numbers.
    ValueError
        ``arm`` not finite and > 0; ``c`` or ``d`` not (4,), not finite or not > 0.
    """
    p = check_params(params)
    _, b = linearize_analytical(p)
    return b @ mixer_matrix(p, c=c, d=d, arm=resolve_arm(p, arm))  # report eqs. (2.12), (4.3)


def pwm_input_matrix(
    params: ARDrone2Params,
    *,
    arm: float | None = None,
    c: FloatArray | None = None,
    d: FloatArray | None = None,
) -> FloatArray:
    """``B_pwm`` (12, 4): small motor-command deviations (%) around the hover trim.

    ``d pwm_bar_i / d pwm_i = 2 (pwm0 + k)`` at the nominal hover command ``pwm0``
    (:func:`visloc.model.hover_pwm`, every motor the same), so
    ``B_pwm = B Gamma * 2 (pwm0 + k)`` (report eqs. 2.12, 2.15 and 4.3).

    Parameters
    ----------
    params, arm, c, d
        As for :func:`mixer_input_matrix`.

    Returns
    -------
    ndarray (12, 4)
        ``d xdot_P / d pwm`` of motors 1-4, state order :data:`PILOT_STATE_NAMES`: per
        percent of motor command.

    Raises
    ------
    TypeError, ValueError
        As for :func:`mixer_input_matrix`.
    """
    p = check_params(params)
    slope = 2.0 * (hover_pwm(p) + p.k)  # d (pwm + k)^2 / d pwm at the trim, %
    return mixer_input_matrix(p, arm=arm, c=c, d=d) * slope
