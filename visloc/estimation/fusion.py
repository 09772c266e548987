"""Position and velocity from map-pose fixes and the accelerometer: the one fusion that
``visloc localize``, ``visloc demo`` and the simulator's vision estimator use.

A constant-velocity Kalman filter (:class:`visloc.estimation.PositionVelocityKF`, filterpy
inside) in the map's (or the simulator's inertial) axes:

- **prediction** to each new time, with the accelerometer as the control input when there is
  one: the specific force ``f`` (body or camera axes, m/s^2) turned into the filter's axes by
  the current attitude ``R`` and gravity added, ``a = R f + g`` (report eq. 2.4's force balance);
  its error ``accel_std`` per sample sets ``Q``; without it ``Q`` comes from ``accel_noise``
  (white acceleration, the CV model);
- **correction** by each position fix (a camera centre from
  :func:`visloc.pose.estimate_camera_pose`): its covariance (m^2) plus a floor of
  ``min_fix_std^2 I``, because the corners' noise does not show the map's and the model's errors
  (printing, lens, the flat-floor assumption); a fix without a covariance counts as
  ``fix_std``. Fixes beyond the filter's chi-square gate are rejected (several in a row reset
  it, :class:`PositionVelocityKF`).

The noise model in numbers (defaults): fixes at least 2 mm (``min_fix_std``), 5 mm without a
covariance (``fix_std``); without accelerometer, an acceleration of 2 m/s^2 standard deviation
per step, independent from step to step (``accel_noise``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from visloc._checks import check_real
from visloc.estimation._checks import FloatArray, as_float_array
from visloc.estimation.kalman import PositionVelocityKF

__all__ = ["MapFixFusion"]


class MapFixFusion:
    """Map-pose fixes and accelerometer input in one constant-velocity Kalman filter
    (module docstring).

    Parameters
    ----------
    accel_noise : float
        Standard deviation of the acceleration held constant over each step of the CV model
        when the step has no accelerometer input, m/s^2 per step (``PositionVelocityKF``'s
        ``accel_noise`` with its default ``accel_noise_kind="std"``).
    min_fix_std : float
        Floor on a fix's standard deviation, m.
    fix_std : float
        Standard deviation of a fix given without a covariance, m.
    initial_position, initial_velocity : array_like (3,), optional
        A known start (else the first fix sets the position).
    initial_std : float or sequence of 2 floats
        Standard deviation of the initial position (and velocity), m (and m/s).
    keep_history : bool
        Keep every step for :meth:`PositionVelocityKF.rts_smooth` (``kf``).

    Attributes
    ----------
    kf : PositionVelocityKF
        The filter itself (3 axes, ``model="cv"``).
    fixes, rejected : int
        Fixes used, and fixes not used (beyond the gate, or with a non-finite position or
        covariance).
    """

    def __init__(self, *, accel_noise: float = 2.0, min_fix_std: float = 0.002, fix_std: float = 0.005,
                 initial_position: ArrayLike | None = None, initial_velocity: ArrayLike | None = None,
                 initial_std: float | Sequence[float] = 1.0, keep_history: bool = True) -> None:
        self.min_fix_std = check_real(min_fix_std, "min_fix_std", positive=True)
        self.fix_std = check_real(fix_std, "fix_std", positive=True)
        self.kf = PositionVelocityKF(3, model="cv", accel_noise=accel_noise, initial_position=initial_position,
                                     initial_velocity=initial_velocity, initial_std=initial_std,
                                     keep_history=keep_history)
        self.fixes = 0
        self.rejected = 0

    @property
    def position(self) -> FloatArray:
        """Estimated position (3,), m."""
        return self.kf.position

    @property
    def velocity(self) -> FloatArray:
        """Estimated velocity (3,), m/s."""
        return self.kf.velocity

    @property
    def position_std(self) -> FloatArray:
        """The filter's current standard deviation of the position (3,), m; never NaN: before
        the first fix, the prior's (``initial_std``, or 1000 m per axis without
        ``initial_position``) grown by the predictions since."""
        return np.sqrt(np.clip(np.diag(self.kf.P)[:: self.kf.order], 0, None))

    def predict(self, t: float, specific_force: ArrayLike | None = None, attitude: ArrayLike | None = None, *,
                gravity: ArrayLike = (0.0, 0.0, -9.81), accel_std: float | None = None) -> None:
        """Advance to time ``t`` (s), with one accelerometer reading when given.

        Parameters
        ----------
        t : float
        specific_force : array_like (3,), optional
            The accelerometer's specific force in the sensor's axes, m/s^2 (a mean over the
            step, or one sample).
        attitude : array_like (3, 3), optional
            ``R`` taking sensor axes into the filter's axes (needed with ``specific_force``).
        gravity : array_like (3,)
            Gravity in the filter's axes, m/s^2 (``(0, 0, -9.81)`` for a map with z up;
            ``(0, 0, 9.81)`` in NED).
        accel_std : float, optional
            Error of the acceleration input per step, m/s^2 (sets ``Q``; default: from
            ``accel_noise``).
        """
        accel = None
        if specific_force is not None:
            if attitude is None:
                raise ValueError("predict: specific_force needs the attitude that turns it into the filter's axes")
            R = as_float_array(attitude, "attitude", (3, 3))
            f = as_float_array(specific_force, "specific_force", (3,))
            accel = R @ f + as_float_array(gravity, "gravity", (3,))
        self.kf.predict(t, accel=accel, accel_std=accel_std)

    def fix(self, position: ArrayLike, covariance: ArrayLike | None = None) -> bool:
        """Correct with one position fix (3,), m, and its covariance (3, 3), m^2 (``None``:
        ``fix_std``, at least ``min_fix_std``); the floor ``min_fix_std^2 I`` is added to a given
        covariance. Returns whether the gate let it in.

        Parameters
        ----------
        position : array_like (3,)
            The fix, m, in the filter's axes (e.g. :attr:`visloc.pose.MapPose.position`, map
            frame).
        covariance : array_like (3, 3), optional
            Its covariance, m^2 (e.g. :attr:`visloc.pose.MapPose.position_covariance`); the
            filter uses ``covariance + min_fix_std^2 I``. None: ``max(fix_std, min_fix_std)^2 I``.

        Returns
        -------
        bool
            Whether the fix was used (counted in ``fixes``); False when the gate rejected it or
            the position or covariance was not finite (counted in ``rejected``). A fix beyond
            the gate after ``reset_after`` rejections in a row resets the filter on it and
            counts as used (:class:`PositionVelocityKF`).

        Raises
        ------
        TypeError
            ``position`` or ``covariance`` is not numeric.
        ValueError
            No time yet (:meth:`predict` never called), ``position`` not (3,), ``covariance``
            not (3, 3), or its sum with the floor not symmetric positive definite
            (:meth:`PositionVelocityKF.update_position`).
        """
        floor = self.min_fix_std**2 * np.eye(3)
        if covariance is None:
            R = max(self.fix_std, self.min_fix_std) ** 2 * np.eye(3)
        else:
            R = as_float_array(covariance, "covariance", (3, 3)) + floor
        used = self.kf.update_position(position, R=R)
        self.fixes += used
        self.rejected += not used
        return used
