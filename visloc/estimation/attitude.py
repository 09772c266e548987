"""Roll and pitch from an IMU: accelerometer tilt, gyro integration, complementary filter.

Report §3.1 (eqs. 3.1-3.5). The switching variant (eqs. 3.6-3.11) is in
:mod:`visloc.estimation.switching`.

Conventions
-----------
Body axes
    NED body axes as in the report: x forward, y right, z down. Euler angles Z-Y-X,
    ``R(lambda) = Rz(psi) Ry(theta) Rx(phi)`` maps body vectors into the NED world frame
    (report eq. 2.5). Roll ``phi`` positive = right wing down, pitch ``theta`` positive = nose
    up, yaw ``psi`` positive = nose turning east from north (clockwise seen from above).
Gyro
    Body angular rate ``omega = (p, q, r)`` about body x, y, z, rad/s, right-handed.
Accelerometer
    **Specific force** in body axes, m/s^2: ``f = R(lambda)^T (a - g e3)`` where ``a`` is the
    vehicle's NED acceleration and ``g e3 = (0, 0, 9.81)`` is gravity (pointing down). This is
    what a physical accelerometer (and e.g. PX4's ``sensor_accel``) reports: at rest and level
    it reads ``(0, 0, -9.81)``. The report's accelerometer vector ``a`` measures "the gravity
    vector" instead, ``a = -f`` (at rest ``a_z = +9.81``, hence the report's test
    ``a_z > 0``, eq. 3.6). To feed data recorded in the report's convention, pass ``-a``.
"""

from __future__ import annotations

import math

import numpy as np

from visloc.estimation._checks import (
    FloatArray,
    as_float_array,
    check_dt,
    check_dt_sequence,
    check_real,
)
from visloc.estimation._fused import (
    _TINY_NORM,
    _TWO_PI,
    GRAVITY,
    _FusedAttitude,
    _normalise,
    _vec3,
    wrap_angle,
)

__all__ = [
    "GRAVITY",
    "ComplementaryFilter",
    "GyroIntegrator",
    "accel_tilt",
    "euler_rates_matrix",
    "wrap_angle",
]


def accel_tilt(accel: object) -> tuple[float, float] | tuple[FloatArray, FloatArray]:
    """Roll and pitch from an accelerometer's specific force (report eqs. 3.1-3.2).

    With ``a = -f`` the report's gravity-pointing vector, ``phi_a = atan2(a_y, a_z)`` (eq. 3.1,
    written with ``atan2`` so that it also holds upside down) and
    ``theta_a = -asin(a_x / |a|)`` (eq. 3.2). In terms of the specific force ``f``::

        roll  = atan2(-f_y, -f_z)
        pitch = asin(f_x / |f|)

    Exact only without body acceleration (then ``f = -g R^T e3``).

    Parameters
    ----------
    accel : array_like (3,) or (N, 3)
        Specific force in NED body axes, m/s^2 (level at rest: ``(0, 0, -9.81)``).

    Returns
    -------
    roll, pitch : float or ndarray (N,)
        Radians; roll in ``(-pi, pi]``, pitch in ``[-pi/2, pi/2]``.

    Raises
    ------
    TypeError
        If ``accel`` is not numeric.
    ValueError
        If ``accel`` has the wrong shape, is not finite, or has a zero norm (free fall).
    """
    try:
        f = np.asarray(accel, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"accel must be an array of numbers, got {type(accel).__name__}") from exc
    if f.ndim not in (1, 2) or f.shape[-1] != 3:
        raise ValueError(f"accel must have shape (3,) or (N, 3), got {f.shape}")
    if not np.all(np.isfinite(f)):
        raise ValueError("accel must be finite")
    norm = np.hypot(np.hypot(f[..., 0], f[..., 1]), f[..., 2])  # no overflow for huge readings, as norm's squares
    if np.any(norm < _TINY_NORM):
        raise ValueError("accel must have a non-zero norm (no tilt information in free fall)")
    roll = np.arctan2(-f[..., 1], -f[..., 2])  # report eq. (3.1), a = -f
    pitch = np.arcsin(np.clip(f[..., 0] / norm, -1.0, 1.0))  # report eq. (3.2), a = -f
    if f.ndim == 1:
        return float(roll), float(pitch)
    return roll, pitch


def euler_rates_matrix(roll: float, pitch: float) -> FloatArray:
    """``Q(lambda)``: body rates ``(p, q, r)`` to Z-Y-X Euler angle rates (report eqs. 2.7, 3.3).

    ``d/dt [phi, theta, psi] = Q(phi, theta) @ [p, q, r]``; independent of yaw.

    Parameters
    ----------
    roll, pitch : float
        Radians. Singular at ``|pitch| = pi/2`` (gimbal lock).

    Returns
    -------
    ndarray (3, 3)
    """
    phi = check_real(roll, "roll")
    theta = check_real(pitch, "pitch")
    if abs(math.cos(theta)) < 1e-12:
        raise ValueError(f"pitch must not be +-pi/2 (gimbal lock), got {theta}")
    s, c, t, sec = math.sin(phi), math.cos(phi), math.tan(theta), 1.0 / math.cos(theta)
    return np.array([[1.0, s * t, c * t],  # report eq. (2.7)
                     [0.0, c, -s],
                     [0.0, s * sec, c * sec]])


class GyroIntegrator:
    """Gyro-only attitude: integrate ``lambda' = Q(lambda) omega`` (report eq. 3.3).

    Forward Euler per sample; drifts with any gyro bias (report §3.1.2).

    Parameters
    ----------
    roll, pitch, yaw : float
        Initial Euler angles, rad.

    Attributes
    ----------
    skipped : int
        Samples ignored (the angles held): a gyro reading that was not finite, or a sample at
        gimbal lock (``|cos(pitch)| < 1e-9``, where ``Q(lambda)`` is undefined).
    """

    def __init__(self, roll: float = 0.0, pitch: float = 0.0, yaw: float = 0.0) -> None:
        self.skipped = 0
        self.reset(roll, pitch, yaw)

    def reset(self, roll: float = 0.0, pitch: float = 0.0, yaw: float = 0.0) -> None:
        """Set the integrator to the given Euler angles (rad); ``skipped`` is kept.

        Parameters
        ----------
        roll, pitch, yaw : float
            Z-Y-X Euler angles, rad; normalised to roll, yaw in ``[-pi, pi)`` and pitch in
            ``[-pi/2, pi/2]`` (a pitch beyond +-pi/2 is the same rotation with roll and yaw
            turned by pi).

        Raises
        ------
        TypeError
            An angle is not a real number.
        ValueError
            An angle is not finite.
        """
        self.roll, self.pitch, self.yaw = _normalise(
            check_real(roll, "roll"), check_real(pitch, "pitch"), check_real(yaw, "yaw"))

    def _step(self, p: float, q: float, r: float, dt: float) -> None:
        sp, cp = math.sin(self.roll), math.cos(self.roll)
        ct = math.cos(self.pitch)
        if abs(ct) < 1e-9:  # gimbal lock: Q undefined, hold the angles
            self.skipped += 1
            return
        st = math.sin(self.pitch)
        roll = self.roll + dt * (p + (sp * q + cp * r) * st / ct)  # report eq. (3.3), Q from eq. (2.7)
        pitch = self.pitch + dt * (cp * q - sp * r)
        yaw = self.yaw + dt * (sp * q + cp * r) / ct
        if not (math.isfinite(roll) and math.isfinite(pitch) and math.isfinite(yaw)):  # rates beyond float's range
            self.skipped += 1
            return
        self.roll, self.pitch, self.yaw = _normalise(roll, pitch, yaw)

    def update(self, gyro: object, dt: float) -> tuple[float, float, float]:
        """Integrate one gyro sample over ``dt`` seconds.

        Parameters
        ----------
        gyro : array_like (3,)
            Body rates ``(p, q, r)``, rad/s. A non-finite reading, one whose step overflows,
            or a sample at gimbal lock (``|cos(pitch)| < 1e-9``), is skipped (the angles held)
            and counted in ``skipped``.
        dt : float
            Time since the previous sample, s, > 0.

        Returns
        -------
        roll, pitch, yaw : float
            Radians.
        """
        dt = check_dt(dt)
        p, q, r = _vec3(gyro, "gyro")
        if math.isfinite(p) and math.isfinite(q) and math.isfinite(r):
            self._step(p, q, r, dt)
        else:
            self.skipped += 1
        return self.roll, self.pitch, self.yaw

    def run(self, gyro: object, dt: object) -> FloatArray:
        """Integrate a sequence: ``gyro`` (N, 3) rad/s, ``dt`` s scalar or (N,).

        Same result as repeated :meth:`update`.

        Parameters
        ----------
        gyro : array_like (N, 3)
            Body rates ``(p, q, r)``, rad/s, body axes. A row with a non-finite value is
            skipped (the angles held) and counted in ``skipped``; so is a sample at gimbal lock
            (``|cos(pitch)| < 1e-9``).
        dt : float or array_like (N,)
            Step before each sample, s, > 0.

        Returns
        -------
        ndarray (N, 3)
            ``[roll, pitch, yaw]`` (rad) after each sample.

        Raises
        ------
        TypeError
            ``gyro`` or ``dt`` is not numeric.
        ValueError
            ``gyro`` not (N, 3), ``dt`` neither a number nor (N,), or a step not finite and > 0.
        """
        g = as_float_array(gyro, "gyro", (None, 3))
        steps = check_dt_sequence(dt, len(g)).tolist()
        ok = np.isfinite(g).all(axis=1).tolist()
        out = np.empty((len(g), 3))
        for i, (p, q, r) in enumerate(g.tolist()):
            if ok[i]:
                self._step(p, q, r, steps[i])
            else:
                self.skipped += 1
            out[i] = self.roll, self.pitch, self.yaw
        return out


class ComplementaryFilter(_FusedAttitude):
    """Complementary filter ``lambda_hat' = Q(lambda_hat) omega + c (lambda_a - lambda_hat)``.

    Report eq. 3.4, on roll and pitch. Its transfer function (eq. 3.5) is
    ``Lambda_hat(s) = s/(s + c) Lambda_g(s) + 1/(s/c + 1) Lambda_a(s)``: a first-order
    high-pass on the integrated gyro and the complementary low-pass on the accelerometer
    angles, crossing over at ``c`` rad/s (``f_c = c / 2 pi`` Hz).

    Discretisation: over each step the gyro term ``u = Q(lambda_hat) omega`` and the accelerometer
    angles ``lambda_a`` are held constant and the linear ODE is solved exactly,
    ``lambda_hat += (1 - e^{-c dt}) (lambda_a - lambda_hat) + (1 - e^{-c dt}) / c * u``.

    With a constant gyro bias ``b`` the plain filter settles at an error of about ``b / c``
    (report §3.1.3: "the drift is bounded to a steady-state error"). The report notes that
    ``c`` "can be chosen more complex to remove this steady-state error": ``bias_gain = k_i > 0``
    makes the correction proportional-integral, ``c + k_i / s``, with the integral state kept
    as a body-frame gyro bias estimate ``b_hat``::

        lambda_hat' = Q(lambda_hat) (omega - b_hat) + c e,     e = lambda_a - lambda_hat
        b_hat'      = -k_i W(lambda_hat) [e, 0]                W = Q^-1

    so the error obeys ``s^2 + c s + k_i`` (critically damped at ``k_i = c^2 / 4``).

    Parameters
    ----------
    crossover_hz : float, optional
        Crossover frequency ``f_c`` (Hz), ``c = 2 pi f_c``. Give this or ``gain``.
    gain : float, optional
        The gain ``c`` (1/s) directly.
    bias_gain : float
        ``k_i`` (1/s^2) of the gyro-bias integrator; 0 (default) is the report's filter.
    initial : (roll, pitch), optional
        Initial estimate, rad; by default the first usable accelerometer sample (eqs. 3.1-3.2).
    bias : array_like (3,), optional
        Initial gyro bias estimate (rad/s), e.g. from a calibration at rest; default zeros.
    settle_seconds : float
        Fast start: for this long after initialisation the crossover is raised to
        ``settle_hz`` (and ``bias_gain`` by the same factor squared, keeping the damping), so
        the attitude and the bias settle quickly. Meant for the seconds a drone sits still
        before take-off; settling fast under body acceleration lets it into the bias estimate.
    settle_hz : float
        Crossover during the fast start, Hz (ignored when not above ``crossover_hz``).

    Attributes
    ----------
    roll, pitch : float
        Current estimate, rad.
    bias : ndarray (3,)
        Current gyro bias estimate, rad/s (stays zero when ``bias_gain == 0``).
    elapsed : float
        Time integrated since the filter was initialised (by ``initial``, the first usable
        sample or the last :meth:`reset`), s (drives the fast start).
    skipped : int
        Samples ignored (the state unchanged) because a reading was not finite, or, for
        readings too large to integrate, the new estimate was not. A sample at gimbal lock
        (``|cos(pitch)| < 1e-9``) is not counted: it re-initialises the estimate from the
        accelerometer.
    """

    def __init__(self, crossover_hz: float | None = None, *, gain: float | None = None,
                 bias_gain: float = 0.0, initial: object = None, bias: object = None,
                 settle_seconds: float = 0.0, settle_hz: float = 0.2) -> None:
        if (crossover_hz is None) == (gain is None):
            raise ValueError("give exactly one of crossover_hz and gain")
        if gain is None:
            self.c = _TWO_PI * check_real(crossover_hz, "crossover_hz", positive=True)
        else:
            self.c = check_real(gain, "gain", positive=True)
        self.bias_gain = check_real(bias_gain, "bias_gain", nonneg=True)
        self.settle_seconds = check_real(settle_seconds, "settle_seconds", nonneg=True)
        self.settle_c = _TWO_PI * check_real(settle_hz, "settle_hz", positive=True)
        self.elapsed = 0.0
        super().__init__(initial)
        b = np.zeros(3) if bias is None else as_float_array(bias, "bias", (3,))
        if not np.all(np.isfinite(b)):
            raise ValueError("bias must be finite")
        self._b = [float(v) for v in b]

    @property
    def bias(self) -> FloatArray:
        """Gyro bias estimate ``(b_p, b_q, b_r)``, rad/s, (3,)."""
        return np.array(self._b)

    def reset(self, roll: float, pitch: float, *, bias: object = None) -> None:
        """Set the estimate to ``(roll, pitch)`` (rad); the bias estimate is kept unless given.

        A new initialisation: the filter counts as initialised afterwards and ``elapsed`` is set
        to 0, so the fast start (``settle_seconds``) runs again; ``skipped`` is kept. Nothing
        changes when an argument is refused.

        Parameters
        ----------
        roll, pitch : float
            The estimate, rad; normalised to roll in ``[-pi, pi)``, pitch in ``[-pi/2, pi/2]``.
        bias : array_like (3,), optional
            New gyro bias estimate ``(b_p, b_q, b_r)``, rad/s, body axes; None keeps the current
            one.

        Raises
        ------
        TypeError
            ``roll`` or ``pitch`` is not a real number, or ``bias`` is not numeric.
        ValueError
            ``roll`` or ``pitch`` not finite, or ``bias`` not (3,) or not finite.
        """
        check_real(roll, "roll")
        check_real(pitch, "pitch")
        if bias is not None:
            b = as_float_array(bias, "bias", (3,))
            if not np.all(np.isfinite(b)):
                raise ValueError("bias must be finite")
        super().reset(roll, pitch)
        if bias is not None:
            self._b = [float(v) for v in b]
        self.elapsed = 0.0

    def _step(self, p: float, q: float, r: float, fx: float, fy: float, fz: float,
              dt: float) -> None:
        norm = math.sqrt(fx * fx + fy * fy + fz * fz)
        if not self.initialised:
            self._start(fx, fy, fz, norm)
            return
        phi, theta = self.roll, self.pitch
        sp, cp, ct = math.sin(phi), math.cos(phi), math.cos(theta)
        if abs(ct) < 1e-9:  # gimbal lock: Q undefined (eq. 2.7); re-initialise from the accel
            self._start(fx, fy, fz, norm)
            return
        b = self._b
        wp, wq, wr = p - b[0], q - b[1], r - b[2]
        u_phi = wp + (sp * wq + cp * wr) * math.sin(theta) / ct  # report eqs. (2.7), (3.3)
        u_theta = cp * wq - sp * wr
        if norm >= _TINY_NORM:
            e_phi = wrap_angle(math.atan2(-fy, -fz) - phi)  # report eq. (3.1)
            e_theta = math.asin(max(-1.0, min(1.0, fx / norm))) - theta  # report eq. (3.2)
        else:  # free fall: the accelerometer holds no attitude information
            e_phi = e_theta = 0.0
        c, ki = self.c, self.bias_gain
        if self.elapsed < self.settle_seconds and self.settle_c > c:  # fast start
            ki *= (self.settle_c / c) ** 2
            c = self.settle_c
        k = -math.expm1(-c * dt)
        h = k / c
        roll, pitch, _ = _normalise(phi + k * e_phi + h * u_phi,  # report eq. (3.4)
                                    theta + k * e_theta + h * u_theta)
        if not (math.isfinite(roll) and math.isfinite(pitch)):
            self.skipped += 1
            return
        self.roll, self.pitch = roll, pitch
        self.elapsed += dt
        if ki:
            ki *= dt  # b_hat' = -k_i W(lambda_hat) [e, 0]
            b[0] -= ki * e_phi
            b[1] -= ki * cp * e_theta
            b[2] += ki * sp * e_theta
