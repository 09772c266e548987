"""The quadrotor mounted on a gimbal stand (report Appendix C, eqs. C.1-C.11).

On the stand the centre of gravity can only rotate about the joint, a distance ``l`` from it
along the body z axis: the state is ``x = [phi, theta, psi, p, q, r]`` (eq. C.10) and the input
``u = [T, tau_x, tau_y, tau_z]`` (eq. C.11), of which the thrust only loads the joint.

Sign of ``l``. ``l > 0``: the joint lies *below* the centre of gravity (the drone sits on top of
the stand), so gravity tips it over like an inverted pendulum; ``l < 0``: the joint lies above
(the drone hangs), so gravity rights it. The vector from the joint to the CoG is ``-l e3`` in
body axes (body z points down).

Gravity torque. Eq. (C.2) gives ``-l R(lambda) e3 x m g e3`` in the inertial frame; in body
axes (where Euler's equation lives) this is ``m g l [cos(theta) sin(phi), sin(theta), 0]``,
independent of the yaw. The report's written-out (C.6)-(C.7) keep the inertial-frame
components (they depend on ``psi``), and (C.7) has the opposite sign of the ``sin(theta)``
term from the one (C.2) gives, which would make roll unstable but pitch stable on the same
stand. This module uses the body-frame torque of (C.2); at ``psi = 0`` its roll component
equals (C.6) for ``theta = 0``. The moments of inertia about the joint are ``I + m l^2``
(parallel axes, the denominators of C.6-C.7).
"""

from __future__ import annotations

import math
import numbers

import numpy as np
from numpy.typing import ArrayLike

from visloc.model.params import ARDrone2Params, check_params
from visloc.model.rigid_body import _vector, euler_rate_matrix
from visloc.types import FloatArray

__all__ = ["STAND_STATE_NAMES", "stand_derivatives", "stand_gravity_torque", "stand_inertia", "stand_linear"]

STAND_STATE_NAMES: tuple[str, ...] = ("phi", "theta", "psi", "p", "q", "r")
"""State of the stand model (report eq. C.10): Z-Y-X Euler angles (rad), body rates (rad/s)."""


def _arm(l: float) -> float:
    if isinstance(l, bool) or not isinstance(l, numbers.Real) or not math.isfinite(l):  # numpy scalars too
        raise ValueError(f"l: expected a finite joint distance in m, got {l!r}")
    return float(l)


def stand_inertia(params: ARDrone2Params, l: float) -> FloatArray:
    """Moments of inertia about the joint, ``[Ixx + m l^2, Iyy + m l^2, Izz]`` (parallel axes).

    Parameters
    ----------
    params : ARDrone2Params
        Mass (kg) and ``Ixx, Iyy, Izz`` (kg m^2).
    l : float
        Joint distance along body z, m (module docstring for its sign).

    Returns
    -------
    ndarray (3,)
        Moments of inertia about the body x, y, z axes through the joint, kg m^2.

    Raises
    ------
    TypeError
        ``params`` is not an :class:`ARDrone2Params`.
    ValueError
        ``l`` is not a finite number.
    """
    p = check_params(params)
    arm = _arm(l)
    return np.array([p.Ixx + p.mass * arm**2, p.Iyy + p.mass * arm**2, p.Izz])


def stand_gravity_torque(lam: ArrayLike, params: ARDrone2Params, l: float) -> FloatArray:
    """Gravity torque about the joint in body axes (3,), N m (report eq. C.2, see module notes).

    Parameters
    ----------
    lam : array_like (3,)
        ``[phi, theta, psi]``, rad.
    params : ARDrone2Params
        Mass and ``g``.
    l : float
        Joint distance along body z, m (> 0: joint below the CoG).

    Returns
    -------
    ndarray (3,)
        ``m g l [cos(theta) sin(phi), sin(theta), 0]``, N m, body axes.

    Raises
    ------
    TypeError
        ``lam`` not real numbers, or ``params`` not an :class:`ARDrone2Params`.
    ValueError
        ``lam`` not (3,) or not finite; ``l`` not a finite number.
    """
    phi, theta, _ = _vector(lam, "lam", 3)
    p = check_params(params)
    w = p.mass * p.g * _arm(l)
    return w * np.array([math.cos(theta) * math.sin(phi), math.sin(theta), 0.0])


def stand_derivatives(state: ArrayLike, u: ArrayLike, params: ARDrone2Params, *, l: float,
                      gyroscopic: bool = False) -> FloatArray:
    """Time derivative of the stand model (report eqs. C.1-C.8).

    Parameters
    ----------
    state : array_like (6,)
        ``[phi, theta, psi, p, q, r]`` (eq. C.10): Z-Y-X Euler angles (rad) and body rates
        (rad/s).
    u : array_like (4,)
        ``[T, tau_x, tau_y, tau_z]`` (eq. C.11), N and N m (body axes); ``T`` acts through the
        joint and is ignored.
    params : ARDrone2Params
        Mass, inertia, ``g``.
    l : float
        Joint distance, m (module docstring for its sign).
    gyroscopic : bool
        Include ``-omega x J omega`` with ``J`` about the joint (Euler's equation; see
        :func:`visloc.model.derivatives` on the report's sign of that term).

    Returns
    -------
    ndarray (6,)
        ``d state / dt``: Euler angle rates (rad/s) and body angular accelerations (rad/s^2).

    Raises
    ------
    TypeError
        As :func:`visloc.model.derivatives`.
    ValueError
        ``state`` not (6,) or ``u`` not (4,), or not finite; ``l`` not a finite number;
        ``theta`` at the Z-Y-X singularity.
    """
    s = _vector(state, "state", 6)
    inputs = _vector(u, "u", 4)
    if not isinstance(gyroscopic, bool):
        raise TypeError(f"gyroscopic: expected bool, got {type(gyroscopic).__name__}")
    inertia = stand_inertia(params, l)
    omega = s[3:6]
    lam_dot = euler_rate_matrix(s[0:3]) @ omega  # report eq. (C.1) / (C.3)-(C.5)
    moment = inputs[1:4] + stand_gravity_torque(s[0:3], params, l)  # report eq. (C.2)
    if gyroscopic:
        moment = moment - np.cross(omega, inertia * omega)
    return np.concatenate([lam_dot, moment / inertia])  # report eqs. (C.6)-(C.8)


def stand_linear(params: ARDrone2Params, l: float) -> tuple[FloatArray, FloatArray]:
    """The linear stand model ``x' = A x + B u`` at rest upright (report eq. C.9).

    Parameters
    ----------
    params : ARDrone2Params
        Mass, inertia, ``g``.
    l : float
        Joint distance along body z, m (module docstring for its sign).

    Returns
    -------
    A : ndarray (6, 6)
        Couples the angles to the rates (identity block) and the roll and pitch tilts to the
        angular accelerations with ``m g l / (I + m l^2)`` (1/s^2); state order
        :data:`STAND_STATE_NAMES`.
    B : ndarray (6, 4)
        Maps ``u = [T, tau_x, tau_y, tau_z]`` (N, N m) through the inverse inertia about the
        joint (1/(kg m^2)); its thrust column is zero.

    Raises
    ------
    TypeError, ValueError
        As :func:`stand_inertia`.
    """
    p = check_params(params)
    inertia = stand_inertia(p, l)
    a = np.zeros((6, 6))
    a[0:3, 3:6] = np.eye(3)  # report eq. (C.1) at lambda = 0
    a[3, 0] = p.mass * p.g * _arm(l) / inertia[0]  # report eq. (C.6) linearised
    a[4, 1] = p.mass * p.g * _arm(l) / inertia[1]  # report eq. (C.7) linearised (sign: C.2)
    b = np.zeros((6, 4))
    b[3:6, 1:4] = np.diag(1.0 / inertia)
    return a, b
