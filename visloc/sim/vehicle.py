"""The simulated AR.Drone 2.0: motors, propulsion and the non-linear rigid body, integrated by RK4.

Each motor ``i`` turns its command ``pwm_i`` (percent, saturated to ``[0, 100]``) into
``T_i = c_i (pwm_i + k)^2`` and ``tau_i = d_i (pwm_i + k)^2`` (report eqs. 2.15-2.18) with its
*own* coefficients ``c_i, d_i``: the controller only knows their mean, so the spread of the
motors acts on the loop as it does on the real drone (report §4.3). An optional first-order
lag (eq. 2.13) sits between the command and the squared term. The rigid body is the model of
:func:`visloc.model.derivatives` (NED, Z-Y-X Euler angles, eqs. 2.1-2.8), with an optional
external force (a push, report Figure 4.5) in the inertial frame.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from numpy.typing import ArrayLike

from visloc.control._checks import as_array, check_params, check_real, resolve_arm
from visloc.control.robustness import max_sigma
from visloc.model.params import ARDRONE2, ARDrone2Params
from visloc.model.propulsion import mixer_matrix, pwm_bar, pwm_bar_values
from visloc.model.rigid_body import rhs_values, rk4_values, rotation_values
from visloc.types import FloatArray

__all__ = ["Vehicle", "motor_coefficients"]


def motor_coefficients(params: ARDrone2Params, n_sigma: float = 0.0, *,
                       seed: int | None = 0) -> tuple[FloatArray, FloatArray]:
    """Thrust and torque coefficients of motors 1-4 at ``+- n_sigma`` standard deviations.

    Parameters
    ----------
    params : ARDrone2Params
        Supplies ``c_mean, c_std, d_mean, d_std`` (report Table 2.3).
    n_sigma : float
        Distance of each coefficient from its mean in standard deviations (>= 0); 0 gives the
        nominal (mean) motors.
    seed : int or None
        Chooses the sign of each of the eight deviations (a vertex of the report's polytope,
        §4.3); None gives the worst-looking vertex for roll: motors 1 and 4 (left) strong,
        2 and 3 (right) weak, and the yaw torques of motors 1 and 3 strong.

    Returns
    -------
    c, d : ndarray (4,)
        Thrust (N/%^2) and torque (N m/%^2) coefficients of motors 1-4.

    Raises
    ------
    TypeError
        ``params`` is not an :class:`ARDrone2Params` or ``n_sigma`` not a real number.
    ValueError
        ``n_sigma`` negative or not finite, or so large that a coefficient is not > 0.
    """
    p = check_params(params)
    n = check_real(n_sigma, "n_sigma", nonneg=True)
    if seed is None:
        sc = np.array([1.0, -1.0, -1.0, 1.0])
        sd = np.array([1.0, -1.0, 1.0, -1.0])
    else:
        signs = np.random.default_rng(seed).choice([-1.0, 1.0], size=8)
        sc, sd = signs[:4], signs[4:]
    c = p.c_mean + n * p.c_std * sc  # report eq. (4.12): c_i = c_mean + r_i sigma_c
    d = p.d_mean + n * p.d_std * sd  # report eq. (4.13): d_i = d_mean + s_i sigma_d
    if np.any(c <= 0) or np.any(d <= 0):
        raise ValueError(f"n_sigma: {n} standard deviations give a non-positive coefficient "
                         f"(at most {max_sigma(p):.3g} for these parameters)")
    return c, d


class Vehicle:
    """The non-linear quadrotor with per-motor propulsion, integrated by fixed-step RK4.

    Parameters
    ----------
    params : ARDrone2Params
        Mass, inertia, ``g``, ``k`` (and ``arm`` unless given).
    c, d : array_like (4,), optional
        Thrust and torque coefficients of motors 1-4 (default the means; see
        :func:`motor_coefficients`).
    arm : float, optional
        Arm distance of eq. (2.12), m (:func:`visloc.control.resolve_arm`).
    motor_lag : float
        Time constant of the first-order motor lag of eq. (2.13), s; 0 (the report's model)
        applies commands at once.
    gyroscopic : bool
        Include the gyroscopic term (see :func:`visloc.model.derivatives`).
    state : array_like (12,), optional
        Initial state (:data:`visloc.model.STATE_NAMES`); default at rest at the origin.
    pwm_max : float
        Command saturation, percent.

    Attributes
    ----------
    state : ndarray (12,)
        Current state.
    time : float
        Simulated time, s.
    pwm : ndarray (4,)
        Last applied (saturated) commands, percent.
    """

    def __init__(self, params: ARDrone2Params = ARDRONE2, *, c: ArrayLike | None = None,
                 d: ArrayLike | None = None, arm: float | None = None, motor_lag: float = 0.0,
                 gyroscopic: bool = False, state: ArrayLike | None = None,
                 pwm_max: float = 100.0) -> None:
        p = check_params(params)
        self.arm = resolve_arm(p, arm)
        self.params = replace(p, arm=self.arm)
        self.c = self.params.c_motors if c is None else as_array(c, "c", (4,))
        self.d = self.params.d_motors if d is None else as_array(d, "d", (4,))
        self.gamma = mixer_matrix(self.params, c=self.c, d=self.d)  # report eq. (2.12)
        self.motor_lag = check_real(motor_lag, "motor_lag", nonneg=True)
        if not isinstance(gyroscopic, bool):
            raise TypeError(f"gyroscopic: expected bool, got {type(gyroscopic).__name__}")
        self.gyroscopic = gyroscopic
        self.pwm_max = check_real(pwm_max, "pwm_max", positive=True)
        self.inertia = np.array([p.Ixx, p.Iyy, p.Izz])
        self._inertia = self.inertia.tolist()
        self.state = np.zeros(12) if state is None else as_array(state, "state", (12,)).copy()
        self.time = 0.0
        self.pwm = np.zeros(4)
        self._bar = np.zeros(4)  # lagged (pwm + k)^2 of each motor, %^2
        self._last_key: bytes | None = None  # the last command's bytes, its (pwm + k)^2 and inputs
        self._target = self._bar
        self._u = [0.0] * 4

    @property
    def inputs(self) -> FloatArray:
        """``[T, tau_x, tau_y, tau_z]`` (4,) the motors give now, N and N m."""
        return self.gamma @ self._bar  # report eq. (2.11)

    def trim(self, pwm: ArrayLike) -> None:
        """Set the motors to ``pwm`` at once (no lag), e.g. hover trim before the start.

        Parameters
        ----------
        pwm : array_like (4,)
            Commands of motors 1-4, percent (clipped to ``[0, pwm_max]``).

        Raises
        ------
        TypeError
            ``pwm`` not numbers.
        ValueError
            ``pwm`` not four finite numbers.
        """
        self.pwm = np.clip(as_array(pwm, "pwm", (4,)), 0.0, self.pwm_max)
        self._bar = pwm_bar(self.pwm, self.params.k)

    def acceleration(self, force: FloatArray | None = None) -> FloatArray:
        """The inertial acceleration now (for the accelerometer), report eq. (2.2).

        Parameters
        ----------
        force : array_like (3,), optional
            External force on the CoG, N, in A.

        Returns
        -------
        ndarray (3,)
            ``nu'``, m/s^2, in A (NED).

        Raises
        ------
        TypeError, ValueError
            ``force`` not 3 finite numbers.
        """
        f = None if force is None else as_array(force, "force", (3,)).tolist()
        u = self._u if self.motor_lag == 0.0 and self._bar is self._target else self.inputs.tolist()
        p = self.params
        return np.array(rhs_values(self.state.tolist(), u, p.mass, p.g, self._inertia, gyroscopic=self.gyroscopic,
                                   force=f)[3:6])

    def step(self, pwm: ArrayLike, dt: float, force: ArrayLike | None = None) -> FloatArray:
        """Apply ``pwm`` for ``dt`` seconds; return the new state.

        Parameters
        ----------
        pwm : array_like (4,)
            Motor commands, percent (clipped to ``[0, pwm_max]``).
        dt : float
            Step, s (> 0).
        force : array_like (3,), optional
            External force on the CoG in the inertial frame, N, held over the step.

        Returns
        -------
        ndarray (12,)
            The state after the step (also in :attr:`state`).

        Raises
        ------
        FloatingPointError
            If the state becomes non-finite or reaches the Z-Y-X singularity (the run has
            diverged; the caller reports it).
        """
        h = check_real(dt, "dt", positive=True)
        key = pwm.tobytes() if isinstance(pwm, np.ndarray) else None
        if key is None or key != self._last_key:  # a new command (the substeps of a control step repeat it)
            top = self.pwm_max  # (on floats: np.clip and pwm_bar's arrays cost more than the arithmetic)
            cmd = [min(max(v, 0.0), top) for v in as_array(pwm, "pwm", (4,)).tolist()]
            bar = pwm_bar_values(cmd, self.params.k)  # report eqs. (2.17)-(2.18)
            self._last_key, self._target, self.pwm = key, np.array(bar), np.array(cmd)
        target = self._target
        if self.motor_lag > 0.0:  # report eq. (2.13), solved exactly over the step
            self._bar = target + (self._bar - target) * math.exp(-h / self.motor_lag)
            u = self.inputs.tolist()
        else:
            if self._bar is not target:
                self._bar = target
                self._u = self.inputs.tolist()
            u = self._u
        fl = None if force is None else as_array(force, "force", (3,)).tolist()
        p = self.params
        try:  # classic RK4 on floats
            new = rk4_values(self.state.tolist(), u, h, p.mass, p.g, self._inertia, gyroscopic=self.gyroscopic,
                             force=fl)
        except (OverflowError, ValueError, ZeroDivisionError):  # math's functions on a state gone bad
            new = [math.nan] * 12
        if not all(map(math.isfinite, new)) or abs(math.cos(new[7])) < 1e-6:
            raise FloatingPointError(f"state not finite or at the pitch singularity at "
                                     f"t = {self.time + h:.3f} s: {np.array(new)!r}")
        self.state = np.array(new)
        self.time += h
        return self.state

    def rotation(self) -> FloatArray:
        """Body-to-inertial rotation ``R(lambda)`` (3, 3) of the current state (eq. 2.6)."""
        return np.array(rotation_values(*self.state[6:9].tolist()))  # the state is finite (step checks it)
