"""State estimation (report chapter 3): IMU attitude filters, ultrasound height, observers.

Attitude (report §3.1): :func:`accel_tilt` (eqs. 3.1-3.2), :func:`euler_rates_matrix` (eq. 3.3),
:class:`GyroIntegrator` (gyro only), :class:`ComplementaryFilter` (eqs. 3.4-3.5, optionally with
gyro-bias integral action) and the report's :class:`SwitchingFilter` (eqs. 3.6-3.11). Gyro
rates are body ``(p, q, r)`` in rad/s; the accelerometer gives the specific force in NED body
axes (level at rest ``(0, 0, -9.81)`` m/s^2; the report's ``a`` is its negative); see
:mod:`visloc.estimation.attitude` for the conventions.

Height (report §3.2.1): :func:`ultrasound_height` (eq. 3.13) and its forward model
:func:`ultrasound_reading` (eq. 3.12); heights are positive up (``-z`` of the report's NED depth).

Position/velocity (report eq. 3.14): :func:`luenberger_gains` by pole placement (Ackermann's
formula, :func:`ackermann_observer_gain`, so repeated poles work) and the streaming two-axis
:class:`LuenbergerObserver`; :class:`PositionVelocityKF`, a Kalman filter (filterpy inside) fusing
position fixes, flow velocities and an accelerometer input, with chi-square gating and RTS
smoothing; :class:`MapFixFusion`, the one fusion of map-pose fixes and the accelerometer that
``visloc localize``, the demo and the simulator use, its noise model in one place.
"""

from visloc.estimation.attitude import (
    GRAVITY,
    ComplementaryFilter,
    GyroIntegrator,
    accel_tilt,
    euler_rates_matrix,
    wrap_angle,
)
from visloc.estimation.fusion import MapFixFusion
from visloc.estimation.height import HeightEstimate, ultrasound_height, ultrasound_reading
from visloc.estimation.kalman import PositionVelocityKF
from visloc.estimation.observer import (
    LuenbergerObserver,
    ackermann_observer_gain,
    luenberger_gains,
)
from visloc.estimation.switching import SwitchingFilter

__all__ = [
    "GRAVITY",
    "ComplementaryFilter",
    "GyroIntegrator",
    "HeightEstimate",
    "LuenbergerObserver",
    "MapFixFusion",
    "PositionVelocityKF",
    "SwitchingFilter",
    "accel_tilt",
    "ackermann_observer_gain",
    "euler_rates_matrix",
    "luenberger_gains",
    "ultrasound_height",
    "ultrasound_reading",
    "wrap_angle",
]
