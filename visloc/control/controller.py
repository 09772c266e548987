"""The report's streaming state-feedback controller (report §4.2, Figure 4.4, §4.4).

``u = u0 - K x`` (eq. 4.5) on the pilot-frame error state (eq. 4.1) with integrated position
and heading errors (§4.2.3), gravity feed-forward ``T0 = m g`` (§4.2.2), bounded position
torques for large set-point errors (§4.4) and the motor commands ``pwm = sqrt(Gamma^-1 u) - k``
(eq. 4.6).
"""

from __future__ import annotations

import math
import operator

import numpy as np
from numpy.typing import ArrayLike

from visloc._compiled import use_compiled
from visloc.control._checks import as_array, check_params, check_real, resolve_arm
from visloc.control.design import ControllerGains, ControlSpecs, design_gains
from visloc.control.linear import _pilot_values, hover_input
from visloc.model.params import ARDRONE2, ARDrone2Params
from visloc.model.propulsion import PwmResult, mixer_matrix, pwm_from_bar
from visloc.types import FloatArray

try:  # the compiled feedback law (optional: without a compiler the Python one runs)
    from visloc.control import _feedback
except ImportError:  # pragma: no cover - built with the package
    _feedback = None

_POSITION_COLUMNS = np.r_[0:6, 12:16]  # x_P..w_P and the integrals: the "set-point" part
_POSITION_INDEX = _POSITION_COLUMNS.tolist()


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


def _error_values(s: list[float], sp: list[float]) -> list[float]:
    """The pilot-frame error state (report eq. 4.1) of a state ``s`` (12 floats) from a set
    point ``sp`` (4 floats) as 12 floats, the heading error wrapped
    (:meth:`Controller.error_state`)."""
    x = _pilot_values(s, s[8], sp[:3])
    x[8] = wrap_angle(s[8] - sp[3])
    return x

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
    native : bool, optional
        The feedback law of each step compiled (``visloc.control._feedback``, the same floats):
        None when it was built, True always (``RuntimeError`` when not built), False never.

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
        native: bool | None = None,
    ) -> None:
        self.params = check_params(params)
        if native is not None and not isinstance(native, bool):
            raise TypeError(f"native: expected None or a bool, got {type(native).__name__}")
        self._compiled = use_compiled(native, _feedback, "visloc.control._feedback")  # (True unbuilt: RuntimeError)
        if gains is not None and not isinstance(gains, ControllerGains):
            raise TypeError(f"gains: expected ControllerGains, got {type(gains).__name__}")
        self.gains = design_gains(self.params, specs=specs) if gains is None else gains
        self.arm = resolve_arm(self.params, arm)
        self._gamma = mixer_matrix(self.params, arm=self.arm)  # report eq. (2.12), mean c, d
        self._K = self.gains.K(integral=True)
        for a in (self._gamma, self._K):
            a.setflags(write=False)  # fixed, and what follows is derived from them
        self._gamma_inv = np.linalg.inv(self._gamma)  # report eq. (4.6)'s Gamma^-1
        # the gains and Gamma^-1 as rows of floats: every step multiplies them by 16 and 4
        # numbers, which plain floats do several times faster than small arrays
        self._K_rows = self._K.tolist()
        # the set-point part's columns (§4.4), of the rows of tau_x and tau_y (the bounded ones)
        self._K_setpoint_rows = self._K[1:3, _POSITION_COLUMNS].tolist()
        self._K_bytes = self._K.tobytes()  # the same, as the compiled law reads them
        self._K_setpoint_bytes = self._K[1:3, _POSITION_COLUMNS].tobytes()
        self._gamma_inv_rows = self._gamma_inv.tolist()
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
        return np.array(_error_values(s.tolist(), sp.tolist()))

    def _inputs(self, x: list[float], integral: list[float]) -> tuple[list[float], tuple[bool, ...]]:
        """``u0 + du`` (4 floats) for the error state ``x`` (12 floats) and the integrals (4),
        with the bounds of §4.4 applied, and which bounds were active."""
        xa = x + integral
        du = [-sum(map(operator.mul, row, xa)) for row in self._K_rows]  # report eq. (4.5): u = -K x
        xs = [xa[i] for i in _POSITION_INDEX]
        sx, sy = (-sum(map(operator.mul, row, xs)) for row in self._K_setpoint_rows)  # the set-point part
        # §4.4: bound the set-point part of tau_x, tau_y
        bx, by = self.torque_bound.tolist()
        tx, ty = min(max(sx, -bx), bx), min(max(sy, -by), by)
        du[1], du[2] = (du[1] - sx) + tx, (du[2] - sy) + ty  # the attitude part plus the bounded one
        limit = self.max_thrust_change
        thrust = du[0]
        du[0] = min(max(thrust, -limit), limit)
        # tau_x moves y, tau_y moves x; the thrust bound freezes z
        u = [a + b for a, b in zip(self.u0.tolist(), du, strict=True)]
        return u, (ty != sy, tx != sx, du[0] != thrust, False)

    def _feed_forward(self, x: list[float], psi: float, reference: tuple[ArrayLike, ArrayLike]) -> float:
        """Shift the error state ``x`` (12 floats, in place) by a reference motion and return
        the thrust to add: the reference velocity in the pilot frame, the roll and pitch that
        give the reference acceleration (``x'' = -g theta``, ``y'' = g phi`` near hover, report
        eq. 4.1's frame), and the thrust that keeps the height under that tilt."""
        vx, vy, vz = as_array(reference[0], "reference velocity", (3,)).tolist()
        ax, ay, az = as_array(reference[1], "reference acceleration", (3,)).tolist()
        c, s = math.cos(psi), math.sin(psi)  # R_psi^T: A -> pilot frame
        g, m = self.params.g, self.params.mass
        up = g - az  # z points down
        theta = math.atan2(-(c * ax + s * ay), up)
        phi = math.atan2((-s * ax + c * ay) * math.cos(theta), up)
        x[3], x[4], x[5] = x[3] - (c * vx + s * vy), x[4] - (-s * vx + c * vy), x[5] - vz
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
        return np.array(self._command_values(state, setpoint, dt, reference))

    def _command_values(self, state: ArrayLike, setpoint: ArrayLike, dt: float,
                        reference: tuple[ArrayLike, ArrayLike] | None) -> list[float]:
        """:meth:`command`'s ``u`` as 4 floats (its arguments checked as it says)."""
        step = check_real(dt, "dt", nonneg=True)
        s = as_array(state, "state", (12,)).tolist()
        x = _error_values(s, as_array(setpoint, "setpoint", (4,)).tolist())
        thrust_ff = 0.0 if reference is None else self._feed_forward(x, s[8], reference)
        u, integral = self._feedback_values(x, step)
        self._integral = np.array(integral)
        u[0] += thrust_ff
        return u

    def _feedback_values(self, x: list[float], step: float) -> tuple[list[float], list[float]]:
        """``u0 - K [x; integral]`` (4 floats) for the error state ``x`` (12 floats) after the
        integrators advance by ``step`` s, and the new integrals (4 floats). Compiled
        (``visloc.control._feedback``) unless ``native`` was False or it was not built: the
        same operations in the same order."""
        integral = self._integral.tolist()
        zone, rate_zone = self.integral_zone.tolist(), self.integral_rate_zone.tolist()
        if self._compiled:
            return _feedback.feedback(x, integral, step, self._K_bytes, self._K_setpoint_bytes,
                                      self.torque_bound.tolist(), self.max_thrust_change, self.u0.tolist(), zone,
                                      rate_zone)
        _, clipped = self._inputs(x, integral)
        e, rate = (x[0], x[1], x[2], x[8]), (x[3], x[4], x[5], x[11])
        # §4.2.3: integrate unless that axis's command is clipped or it moves outside its zone
        integral = [i if c or (abs(a) > z and abs(b) > w) else i + a * step for i, c, a, b, z, w
                    in zip(integral, clipped, e, rate, zone, rate_zone, strict=True)]
        u, _ = self._inputs(x, integral)
        return u, integral

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
        u = self._command_values(state, setpoint, dt, reference)
        bar = [sum(map(operator.mul, row, u)) for row in self._gamma_inv_rows]
        return pwm_from_bar(np.array(bar), self.params.k)  # report eq. (4.6): sqrt(Gamma^-1 u) - k
