"""The report's streaming state-feedback controller (report §4.2, Figure 4.4, §4.4).

``u = u0 - K x`` (eq. 4.5) on the pilot-frame error state (eq. 4.1) with integrated position
and heading errors (§4.2.3), gravity feed-forward ``T0 = m g`` (§4.2.2), bounded position
torques for large set-point errors (§4.4) and the motor commands ``pwm = sqrt(Gamma^-1 u) - k``
(eq. 4.6).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from visloc.control._checks import as_array, check_params, check_real, resolve_arm
from visloc.control.design import ControllerGains, ControlSpecs, design_gains
from visloc.control.linear import _pilot_state, hover_input
from visloc.model.params import ARDRONE2, ARDrone2Params
from visloc.model.propulsion import PwmResult, mixer_matrix, pwm_from_bar
from visloc.types import FloatArray

_POSITION_COLUMNS = np.r_[0:6, 12:16]  # x_P..w_P and the integrals: the "set-point" part


def wrap_angle(angle: float | FloatArray) -> float | FloatArray:
    """``angle`` wrapped to [-pi, pi).

    Parameters
    ----------
    angle : float or ndarray
        Angle(s), rad (an array is wrapped elementwise).

    Returns
    -------
    float or ndarray
        The same angle(s) modulo ``2 pi``, rad, in [-pi, pi).
    """
    wrapped = (angle + math.pi) % (2.0 * math.pi) - math.pi
    if isinstance(wrapped, np.ndarray):
        return np.where(wrapped >= math.pi, wrapped - 2.0 * math.pi, wrapped)
    return wrapped - 2.0 * math.pi if wrapped >= math.pi else wrapped  # the modulo can round up to 2 pi


def _zone(value: tuple[float, float], name: str) -> FloatArray:
    if not isinstance(value, (tuple, list)) or len(value) != 2:
        raise ValueError(f"{name}: expected (position, heading), got {value!r}")
    position = check_real(value[0], f"{name}[0]", positive=True)
    heading = check_real(value[1], f"{name}[1]", positive=True)
    return np.array([position] * 3 + [heading])


class Controller:
    """Full-state feedback with integral action for the AR.Drone 2.0 (report Figure 4.4).

    Parameters
    ----------
    params : ARDrone2Params
        Vehicle parameters (mass and g for the feed-forward, the mixer for :meth:`pwm`).
    gains : ControllerGains, optional
        Default :func:`visloc.control.design_gains` of ``params`` and ``specs``.
    specs : ControlSpecs, optional
        Loop specifications used when ``gains`` is not given.
    arm : float, optional
        Arm distance ``d`` of eq. (2.12), m, for the mixer (see
        :func:`visloc.control.resolve_arm`; default ``params.arm``, else 0.125 m).
    max_tilt : float
        Bound on the roll/pitch torque that position, velocity and integrated position
        errors may ask for, as the attitude it would hold against the attitude loop's
        proportional gain, rad (report §4.4: "bound the control torques produced by large
        set-point errors"). Default 0.3 rad (17 degrees); ``math.inf`` disables it.
    max_thrust_change : float, optional
        Bound on the thrust deviation from ``T0 = m g``, N; default ``0.5 m g``.
    integral_zone, integral_rate_zone : (float, float)
        An axis stops integrating while its error is beyond ``integral_zone`` (m, rad) *and*
        it moves faster than ``integral_rate_zone`` (m/s, rad/s): position then heading.
        Defaults (0.3 m, 0.3 rad) and (0.1 m/s, 0.1 rad/s).

    Notes
    -----
    The integrators (pilot-frame x, y, z errors and the heading error, m s and rad s) are
    there for steady-state errors (report §4.2.3). They stop on an axis whose bound is
    active, or that is still travelling towards a distant set point (conditional
    integration), so that set-point steps do not wind them up: with the default
    specifications a 1 m side step overshoots by about 10 % when the integrators run all the
    time and by about 3 % with the default zones (3 m: 7 % and 1.4 %). A steady offset,
    however large, is still integrated away (its rate is zero): the measured spread of the
    motors of quadrotor 4 alone leave a PD loop 16 cm and 0.3 rad off. The linear analysis
    (:func:`visloc.control.vertex_check`) treats the integrators as always running.
    """

    def __init__(
        self,
        params: ARDrone2Params = ARDRONE2,
        *,
        gains: ControllerGains | None = None,
        specs: ControlSpecs | None = None,
        arm: float | None = None,
        max_tilt: float = 0.3,
        max_thrust_change: float | None = None,
        integral_zone: tuple[float, float] = (0.3, 0.3),
        integral_rate_zone: tuple[float, float] = (0.1, 0.1),
    ) -> None:
        self.params = check_params(params)
        if gains is not None and not isinstance(gains, ControllerGains):
            raise TypeError(f"gains: expected ControllerGains, got {type(gains).__name__}")
        self.gains = design_gains(self.params, specs) if gains is None else gains
        self.arm = resolve_arm(self.params, arm)
        self._gamma = mixer_matrix(self.params, arm=self.arm)  # report eq. (2.12), mean c, d
        self._K = self.gains.K(integral=True)
        for a in (self._gamma, self._K):
            a.setflags(write=False)  # fixed, and what follows is derived from them
        self._K_setpoint = self._K[:, _POSITION_COLUMNS]  # the columns of the set-point part (§4.4)
        self._gamma_inv = np.linalg.inv(self._gamma)  # report eq. (4.6)'s Gamma^-1
        tilt = check_real(max_tilt, "max_tilt", positive=True, allow_inf=True)
        self.torque_bound = np.array([self.gains.roll.kp, self.gains.pitch.kp]) * tilt
        self.u0 = hover_input(self.params)  # report §4.2.2: T0 = m g feed-forward
        dt_max = 0.5 * self.u0[0] if max_thrust_change is None else max_thrust_change
        self.max_thrust_change = check_real(dt_max, "max_thrust_change", positive=True)
        self.integral_zone = _zone(integral_zone, "integral_zone")
        self.integral_rate_zone = _zone(integral_rate_zone, "integral_rate_zone")
        self._integral = np.zeros(4)

    @property
    def K(self) -> FloatArray:
        """The designed gains (4, 16) on the 12 pilot-frame states and 4 integrals (read-only)."""
        return self._K

    @property
    def gamma(self) -> FloatArray:
        """The mixer (4, 4) of eq. (2.12) with the mean motor coefficients (read-only)."""
        return self._gamma

    @property
    def integral(self) -> FloatArray:
        """Integrated errors ``[x_P, y_P, z_P, psi]`` (4,), m s and rad s (a copy)."""
        return self._integral.copy()

    def reset(self) -> None:
        """Zero the integrators."""
        self._integral = np.zeros(4)

    def error_state(self, state: ArrayLike, setpoint: ArrayLike) -> FloatArray:
        """Pilot-frame error state (12,) of ``state`` with respect to ``setpoint``.

        Parameters
        ----------
        state : array_like (12,)
            Model state in the inertial NED frame A (:data:`visloc.model.STATE_NAMES`).
        setpoint : array_like (4,)
            ``[x, y, z, psi]``: position in A (m, z down) and heading (rad).

        Returns
        -------
        ndarray (12,)
            ``[R_psi^T (xi - xi_ref), R_psi^T nu, phi, theta, psi - psi_ref, p, q, r]`` with
            the current heading ``psi`` (report eq. 4.1) and the heading error wrapped.
        """
        s = as_array(state, "state", (12,))
        sp = as_array(setpoint, "setpoint", (4,))
        x = _pilot_state(s, float(s[8]), sp[:3])  # report eq. (4.1) (to_pilot, checked above)
        x[8] = wrap_angle(s[8] - sp[3])
        return x

    def _inputs(self, x: FloatArray, integral: FloatArray) -> tuple[FloatArray, tuple[bool, ...]]:
        xa = np.concatenate([x, integral])
        du = -(self.K @ xa)  # report eq. (4.5): u = -K x
        setpoint_part = -(self._K_setpoint @ xa[_POSITION_COLUMNS])
        attitude_part = du - setpoint_part
        # §4.4: bound the set-point part of tau_x, tau_y (np.clip on floats: min(max(v, -b), b))
        bx, by = self.torque_bound.tolist()
        sx, sy = float(setpoint_part[1]), float(setpoint_part[2])
        tx, ty = min(max(sx, -bx), bx), min(max(sy, -by), by)
        du[1], du[2] = float(attitude_part[1]) + tx, float(attitude_part[2]) + ty
        limit = self.max_thrust_change
        thrust = float(du[0])
        dt_limited = min(max(thrust, -limit), limit)
        du[0] = dt_limited
        # tau_x moves y, tau_y moves x; the thrust bound freezes z
        return self.u0 + du, (ty != sy, tx != sx, dt_limited != thrust, False)

    def _feed_forward(self, x: FloatArray, psi: float, reference: tuple[ArrayLike, ArrayLike]) -> float:
        """Shift the error state ``x`` (in place) by a reference motion and return the thrust
        to add: the reference velocity in the pilot frame, the roll and pitch that give the
        reference acceleration (``x'' = -g theta``, ``y'' = g phi`` near hover, report eq. 4.1's
        frame), and the thrust that keeps the height under that tilt."""
        v_ref = as_array(reference[0], "reference velocity", (3,))
        a_ref = as_array(reference[1], "reference acceleration", (3,))
        c, s = math.cos(psi), math.sin(psi)
        rot = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # R_psi^T: A -> pilot frame
        v_p, a_p = rot @ v_ref, rot @ a_ref
        g, m = self.params.g, self.params.mass
        up = g - a_p[2]  # z points down
        theta = math.atan2(-a_p[0], up)
        phi = math.atan2(a_p[1] * math.cos(theta), up)
        x[3:6] -= v_p
        x[6] -= phi
        x[7] -= theta
        return m * up / (math.cos(phi) * math.cos(theta)) - m * g

    def command(self, state: ArrayLike, setpoint: ArrayLike, dt: float, *,
                reference: tuple[ArrayLike, ArrayLike] | None = None) -> FloatArray:
        """Advance the integrators by ``dt`` and return ``u = [T, tau_x, tau_y, tau_z]`` (4,).

        Parameters
        ----------
        state : array_like (12,)
            Estimated state in A (see :meth:`error_state`).
        setpoint : array_like (4,)
            ``[x, y, z, psi]`` in A, m and rad.
        dt : float
            Time since the previous call, s (>= 0; 0 leaves the integrators alone).
        reference : (array_like (3,), array_like (3,)), optional
            The reference's velocity (m/s) and acceleration (m/s^2) in A at this time, when
            ``setpoint`` is a moving reference's position (:class:`visloc.control.trajectory.
            MinJerkTrajectory`): the feedback then acts on the errors from the reference
            motion, and the tilt and thrust that motion needs are fed forward.

        Returns
        -------
        ndarray (4,)
            Thrust (N) and body torques (N m), feed-forward ``T0 = m g`` included.
        """
        step = check_real(dt, "dt", nonneg=True)
        x = self.error_state(state, setpoint)
        thrust_ff = 0.0 if reference is None else self._feed_forward(x, float(np.asarray(state, float)[8]), reference)
        _, clipped = self._inputs(x, self._integral)
        v = x.tolist()
        e, rate = (v[0], v[1], v[2], v[8]), (v[3], v[4], v[5], v[11])
        zone, rate_zone = self.integral_zone.tolist(), self.integral_rate_zone.tolist()
        # §4.2.3: integrate unless that axis's command is clipped or it moves outside its zone
        self._integral = np.array([i if c or (abs(a) > z and abs(b) > w) else i + a * step for i, c, a, b, z, w
                                   in zip(self._integral.tolist(), clipped, e, rate, zone, rate_zone, strict=True)])
        u, _ = self._inputs(x, self._integral)
        u[0] += thrust_ff
        return u

    def pwm(self, state: ArrayLike, setpoint: ArrayLike, dt: float, *,
            reference: tuple[ArrayLike, ArrayLike] | None = None) -> PwmResult:
        """:meth:`command` turned into motor commands, ``pwm = sqrt(Gamma^-1 u) - k`` (eq. 4.6).

        Parameters
        ----------
        state, setpoint, dt, reference
            As for :meth:`command`.

        Returns
        -------
        PwmResult
            Commands of motors 1-4 in percent, with saturation flags, as
            :func:`visloc.model.pwm_from_inputs` gives them with the mean-coefficient mixer
            (whose inverse the controller keeps).
        """
        u = self.command(state, setpoint, dt, reference=reference)
        return pwm_from_bar(self._gamma_inv @ u, self.params.k)  # report eq. (4.6): sqrt(Gamma^-1 u) - k
