"""Rigid-body equations of motion of the quadrotor (report section 2.1, eqs. 2.1-2.8, App. A).

Frames: the inertial frame A is NED (x north, y east, z down; gravity ``+g`` along z) and the
body frame B is x forward, y right, z down, with its origin at the centre of gravity. The
attitude is ``lambda = [phi, theta, psi]`` (Z-Y-X Euler angles: roll, pitch, yaw) and
``R(lambda) = Rz(psi) Ry(theta) Rx(phi)`` maps body-frame vectors into the inertial frame.

State vector (12,), in this order::

    0-2   x, y, z          position of the CoG in A, m            (report xi_A)
    3-5   u, v, w          velocity of the CoG in A, m/s          (report nu_A; NOT body axes)
    6-8   phi, theta, psi  Z-Y-X Euler angles, rad                (report lambda)
    9-11  p, q, r          body angular velocity in B, rad/s      (report omega_x, omega_y, omega_z)

Input ``u = [T, tau_x, tau_y, tau_z]``: total thrust (N) along body -z and body torques (N m).
"""

from __future__ import annotations

import math
import numbers

import numpy as np
from numpy.typing import ArrayLike

from visloc._checks import all_finite
from visloc._compiled import use_compiled
from visloc.model.params import ARDrone2Params, check_params
from visloc.types import FloatArray

try:  # the compiled derivative and RK4 step (optional: without a compiler the Python ones run)
    from visloc.model import _rigid
except ImportError:  # pragma: no cover - built with the package
    _rigid = None

STATE_NAMES: tuple[str, ...] = (
    "x", "y", "z", "u", "v", "w", "phi", "theta", "psi", "p", "q", "r",
)
"""Names of the 12 state entries, in order (see the module docstring for frames and units)."""


def _vector(value: ArrayLike, name: str, size: int) -> FloatArray:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name}: expected real numbers, got {type(value).__name__}") from exc
    if arr.shape != (size,):
        raise ValueError(f"{name}: expected shape ({size},), got {arr.shape}")
    if not all_finite(arr):
        raise ValueError(f"{name}: expected finite values, got {arr!r}")
    return arr


def rotation_matrix(lam: ArrayLike) -> FloatArray:
    """Body-to-inertial rotation ``R = Rz(psi) Ry(theta) Rx(phi)`` (3, 3) (report eqs. 2.5-2.6).

    Parameters
    ----------
    lam : array_like (3,)
        ``[phi, theta, psi]``, rad.

    Returns
    -------
    ndarray (3, 3)
        ``R`` with ``v_A = R @ v_B`` (body frame B into the inertial NED frame A).

    Raises
    ------
    TypeError
        ``lam`` not real numbers.
    ValueError
        ``lam`` not (3,) or not finite.
    """
    return np.array(rotation_values(*_vector(lam, "lam", 3).tolist()))


def rotation_values(phi: float, theta: float, psi: float) -> list[list[float]]:
    """:func:`rotation_matrix` on Python floats, without its argument checks: its three rows
    (the loops of :mod:`visloc.sim` build one at every step, where floats are faster than a
    checked array).

    Parameters
    ----------
    phi, theta, psi : float
        Roll, pitch and yaw, rad.

    Returns
    -------
    list of 3 lists of 3 floats
        The rows of ``R = Rz(psi) Ry(theta) Rx(phi)`` (body to inertial).
    """
    cf, sf = math.cos(phi), math.sin(phi)
    ct, st = math.cos(theta), math.sin(theta)
    cp, sp = math.cos(psi), math.sin(psi)
    return [  # report eq. (2.6)
        [ct * cp, cp * st * sf - cf * sp, sf * sp + cf * cp * st],
        [ct * sp, cf * cp + st * sf * sp, cf * st * sp - cp * sf],
        [-st, ct * sf, ct * cf],
    ]


def _check_pitch(theta: float) -> float:
    """``cos(theta)``, or ValueError when it is below 1e-9 (the Z-Y-X singularity)."""
    ct = math.cos(theta)
    if abs(ct) < 1e-9:
        raise ValueError(f"lam: pitch theta = {theta!r} rad is at the Z-Y-X singularity")
    return ct


def euler_rate_matrix(lam: ArrayLike) -> FloatArray:
    """``Q(lambda)`` (3, 3) with ``d lambda / dt = Q(lambda) omega`` (report eq. 2.7).

    Parameters
    ----------
    lam : array_like (3,)
        ``[phi, theta, psi]``, rad; ``|theta|`` must stay away from ``pi / 2`` (gimbal lock).

    Returns
    -------
    ndarray (3, 3)
        ``Q`` mapping the body rates ``omega = [p, q, r]`` (rad/s, body frame) to the Euler
        angle rates ``[phidot, thetadot, psidot]`` (rad/s).

    Raises
    ------
    TypeError
        ``lam`` not real numbers.
    ValueError
        ``lam`` not (3,) or not finite, or ``cos(theta)`` below 1e-9 (the Z-Y-X singularity).
    """
    phi, theta, _ = _vector(lam, "lam", 3)
    ct = _check_pitch(theta)
    cf, sf, tt = math.cos(phi), math.sin(phi), math.tan(theta)
    return np.array(  # report eq. (2.7)
        [
            [1.0, sf * tt, cf * tt],
            [0.0, cf, -sf],
            [0.0, sf / ct, cf / ct],
        ]
    )


def euler_rate_values(lam: list[float], omega: list[float]) -> list[float]:
    """``Q(lambda) omega`` (report eq. 2.7) on Python floats, without argument checks, as
    :func:`rhs_values` computes it (an attitude integrated from a gyro at every step of
    :mod:`visloc.sim`'s loop).

    Parameters
    ----------
    lam : list of 3 floats
        The Euler angles ``[phi, theta, psi]``, rad (``theta`` away from +-90 deg).
    omega : list of 3 floats
        The body rates ``[p, q, r]``, rad/s.

    Returns
    -------
    list of 3 floats
        The Euler angle rates ``[phi_dot, theta_dot, psi_dot]``, rad/s.
    """
    phi, theta = lam[0], lam[1]
    p, q, r = omega
    cf, sf = math.cos(phi), math.sin(phi)
    ct = math.cos(theta)
    tt = math.sin(theta) / ct
    return [p + (sf * q + cf * r) * tt, cf * q - sf * r, (sf * q + cf * r) / ct]


def derivatives(
    state: ArrayLike,
    u: ArrayLike,
    params: ARDrone2Params,
    *,
    gyroscopic: bool = False,
) -> FloatArray:
    """Time derivative of the 12-state rigid-body model (report eqs. 2.1-2.4 / A.5-A.16).

    Parameters
    ----------
    state : array_like (12,)
        ``[x, y, z, u, v, w, phi, theta, psi, p, q, r]``: NED position (m) and velocity (m/s)
        in the inertial frame, Z-Y-X Euler angles (rad), body rates (rad/s).
    u : array_like (4,)
        ``[T, tau_x, tau_y, tau_z]``: total thrust (N, along body -z) and body torques (N m).
    params : ARDrone2Params
        Supplies ``mass`` (kg), ``J`` (kg m^2) and ``g`` (m/s^2).
    gyroscopic : bool
        Include the gyroscopic term. The report neglects it (A.14-A.16, the default here).
        When True this uses Euler's equation ``J omega' = tau - omega x J omega``; the report's
        eq. (2.4)/(A.4) prints ``+ omega x J omega``, which does not conserve angular momentum.

    Returns
    -------
    ndarray (12,)
        ``d state / dt`` in the units of ``state`` per second.

    Raises
    ------
    TypeError
        ``state`` or ``u`` not real numbers, ``params`` not an :class:`ARDrone2Params`,
        ``gyroscopic`` not a bool.
    ValueError
        ``state`` not (12,) or ``u`` not (4,), a NaN or infinite entry, or ``theta`` at the
        Z-Y-X singularity (:func:`euler_rate_matrix`).
    """
    s = _vector(state, "state", 12)
    u = _vector(u, "u", 4)
    p = check_params(params)
    if not isinstance(gyroscopic, bool):
        raise TypeError(f"gyroscopic: expected bool, got {type(gyroscopic).__name__}")
    _check_pitch(s[7])  # raises at the Z-Y-X singularity, as euler_rate_matrix(s[6:9]) does
    return np.array(rhs_values(s.tolist(), u.tolist(), p.mass, p.g, [p.Ixx, p.Iyy, p.Izz],
                               gyroscopic=gyroscopic))


def rhs(state: FloatArray, u: FloatArray, mass: float, g: float, inertia: FloatArray, *,
        gyroscopic: bool = False) -> FloatArray:
    """:func:`derivatives` without input checks, for integrators that call it many times.

    Parameters
    ----------
    state : ndarray (12,)
        As for :func:`derivatives` (finite, ``|theta| < pi / 2``: not checked).
    u : ndarray (4,)
        ``[T, tau_x, tau_y, tau_z]``, N and N m.
    mass, g : float
        kg and m/s^2.
    inertia : ndarray (3,)
        ``[Ixx, Iyy, Izz]``, kg m^2.
    gyroscopic : bool
        Include ``-omega x J omega`` (see :func:`derivatives`).

    Returns
    -------
    ndarray (12,)
        ``d state / dt`` in the units of ``state`` per second.
    """
    return np.array(rhs_values(np.asarray(state, float).tolist(), np.asarray(u, float).tolist(), mass, g,
                               np.asarray(inertia, float).tolist(), gyroscopic=gyroscopic))


def rhs_values(s: list[float], u: list[float], mass: float, g: float, inertia: list[float], *,
               gyroscopic: bool = False, force: list[float] | None = None, native: bool | None = None) -> list[float]:
    """:func:`rhs` on Python floats (the model's equations; no array is made, so an integrator
    on lists runs several times faster). Compiled (``visloc.model._rigid``) when it was built:
    the same operations in the same order, the same floats.

    Parameters
    ----------
    s : list of 12 floats
        The state, as :func:`derivatives`.
    u : list of 4 floats
        ``[T, tau_x, tau_y, tau_z]``, N and N m.
    mass, g : float
        kg and m/s^2.
    inertia : list of 3 floats
        ``[Ixx, Iyy, Izz]``, kg m^2.
    gyroscopic : bool
        Include ``-omega x J omega`` (see :func:`derivatives`).
    force : list of 3 floats, optional
        External force on the CoG, N, in A: ``force / mass`` joins the acceleration.
    native : bool, optional
        None: the compiled version when it was built; True: it (RuntimeError when not
        built); False: the Python one.

    Returns
    -------
    list of 12 floats
        ``d state / dt``.
    """
    if use_compiled(native, _rigid, "visloc.model._rigid"):
        return _rigid.rhs(s, u, force, mass, g, inertia[0], inertia[1], inertia[2], gyroscopic)
    phi, theta, psi, p, q, r = s[6], s[7], s[8], s[9], s[10], s[11]
    cf, sf = math.cos(phi), math.sin(phi)
    ct, st = math.cos(theta), math.sin(theta)
    cp, sp = math.cos(psi), math.sin(psi)
    a = u[0] / mass
    mx, my, mz = u[1], u[2], u[3]  # report eq. (A.14)-(A.16)
    if gyroscopic:  # Euler's equation (see derivatives): moment - omega x (J omega)
        jx, jy, jz = inertia[0] * p, inertia[1] * q, inertia[2] * r
        mx, my, mz = mx - (q * jz - r * jy), my - (r * jx - p * jz), mz - (p * jy - q * jx)
    out = [
        s[3], s[4], s[5],  # report eq. (2.1) / (A.5)-(A.7)
        # report eq. (2.2) / (A.11)-(A.13): -R e3 T / m + g e3, with R's third column (eq. 2.6)
        -(sf * sp + cf * cp * st) * a,
        -(cf * st * sp - cp * sf) * a,
        g - ct * cf * a,
        # report eq. (2.3) / (A.8)-(A.10): lambda' = Q(lambda) omega, eq. (2.7)
        *euler_rate_values(s[6:8], [p, q, r]),
        mx / inertia[0], my / inertia[1], mz / inertia[2],
    ]
    if force is not None:
        out[3], out[4], out[5] = out[3] + force[0] / mass, out[4] + force[1] / mass, out[5] + force[2] / mass
    return out


def rk4_values(s: list[float], u: list[float], h: float, mass: float, g: float, inertia: list[float], *,
               gyroscopic: bool = False, force: list[float] | None = None, native: bool | None = None) -> list[float]:
    """One classic Runge-Kutta (RK4) step of :func:`rhs_values` on Python floats, the inputs
    and the force held over the step; compiled as :func:`rhs_values` is.

    Parameters
    ----------
    s : list of 12 floats
        The state now, as :func:`derivatives`.
    u : list of 4 floats
        ``[T, tau_x, tau_y, tau_z]``, N and N m, held over the step.
    h : float
        The step, s.
    mass, g, inertia, gyroscopic, force, native
        As :func:`rhs_values`.

    Returns
    -------
    list of 12 floats
        The state after the step. A state gone bad gives non-finite floats (compiled) or
        raises ``ValueError`` / ``ZeroDivisionError`` inside :mod:`math` (Python): the caller
        judges either.
    """
    if use_compiled(native, _rigid, "visloc.model._rigid"):
        return _rigid.rk4(s, u, force, h, mass, g, inertia[0], inertia[1], inertia[2], gyroscopic)
    half, sixth = 0.5 * h, h / 6.0

    def f(x: list[float]) -> list[float]:
        return rhs_values(x, u, mass, g, inertia, gyroscopic=gyroscopic, force=force, native=False)

    k1 = f(s)
    k2 = f([a + half * b for a, b in zip(s, k1, strict=True)])
    k3 = f([a + half * b for a, b in zip(s, k2, strict=True)])
    k4 = f([a + h * b for a, b in zip(s, k3, strict=True)])
    return [a + sixth * (((b + 2.0 * c) + 2.0 * d) + e) for a, b, c, d, e in zip(s, k1, k2, k3, k4, strict=True)]


def motor_lag_derivative(pwm_bar: ArrayLike, pwm_bar_cmd: ArrayLike, tau_c: float) -> FloatArray:
    """First-order motor lag ``d pwm_bar / dt = (pwm_hat - pwm_bar) / tau_c`` (report eq. 2.13).

    The report prints the left-hand side without its time derivative; it means the lagged
    squared term ``pwm_bar`` follows the commanded ``pwm_hat = (pwm + k)^2`` (from
    :func:`visloc.model.pwm_bar`) with time constant ``tau_c``. The report gives no value for
    ``tau_c`` and leaves the lag out of its model.

    Parameters
    ----------
    pwm_bar : array_like (4,)
        Current (lagged) squared terms of motors 1-4, %^2.
    pwm_bar_cmd : array_like (4,)
        Commanded squared terms ``pwm_hat``, %^2.
    tau_c : float
        Time constant, s (> 0).

    Returns
    -------
    ndarray (4,)
        ``d pwm_bar / dt``, %^2/s; ``mixer @ pwm_bar`` gives the lagged ``u``.

    Raises
    ------
    TypeError
        ``pwm_bar`` or ``pwm_bar_cmd`` not real numbers.
    ValueError
        ``pwm_bar`` or ``pwm_bar_cmd`` not (4,) or not finite; ``tau_c`` not a finite number
        > 0.
    """
    x = _vector(pwm_bar, "pwm_bar", 4)
    cmd = _vector(pwm_bar_cmd, "pwm_bar_cmd", 4)
    if isinstance(tau_c, bool) or not isinstance(tau_c, numbers.Real) or not 0 < tau_c < math.inf:
        raise ValueError(f"tau_c: expected a finite time constant > 0 s, got {tau_c!r}")
    return (cmd - x) / tau_c  # report eq. (2.13)
