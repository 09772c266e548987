"""Synthetic IMU streams with exact attitude truth, for testing attitude estimators.

The trajectory is analytic: roll, pitch, yaw and the vehicle's NED acceleration are sums of
sinusoids with random frequencies and phases, so the angles, the body rates and the specific
force are exact at every sample (no numerical integration).

Conventions (those of :mod:`visloc.estimation.attitude`): NED world and body axes (x forward,
y right, z down), Z-Y-X Euler angles with ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (report eq. 2.5),
body rates ``(p, q, r)`` in rad/s, and the accelerometer reporting the specific force
``f = R^T (a - g e3)`` in m/s^2 (level at rest: ``(0, 0, -9.81)``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from visloc._checks import check_int
from visloc.pose.rotations import euler_to_matrix
from visloc.synth._checks import check_number

FloatArray = NDArray[np.float64]
GRAVITY = 9.81
#: Seconds over which the motion fades in after ``rest_seconds`` (:func:`imu_stream`).
RAMP_SECONDS = 5.0


@dataclass(frozen=True, eq=False)
class ImuStream:
    """Sampled IMU readings with their ground truth.

    Attributes
    ----------
    t : ndarray (N,)
        Sample times, s, from 0 at ``1 / rate_hz`` spacing.
    roll, pitch, yaw : ndarray (N,)
        True Z-Y-X Euler angles at ``t``, rad.
    body_rates : ndarray (N, 3)
        True body angular rates ``(p, q, r)``, rad/s.
    accel_ned : ndarray (N, 3)
        True vehicle acceleration in the NED world frame, m/s^2 (z down).
    specific_force : ndarray (N, 3)
        True specific force in body axes, ``R^T (accel_ned - g e3)``, m/s^2.
    gyro : ndarray (N, 3)
        Gyro readings: ``body_rates + gyro_bias + noise``, rad/s.
    accel : ndarray (N, 3)
        Accelerometer readings: ``specific_force + noise``, m/s^2.
    gyro_bias : ndarray (3,)
        The constant gyro bias added, rad/s.
    dt : float
        Sample period, s.
    """

    t: FloatArray
    roll: FloatArray
    pitch: FloatArray
    yaw: FloatArray
    body_rates: FloatArray
    accel_ned: FloatArray
    specific_force: FloatArray
    gyro: FloatArray
    accel: FloatArray
    gyro_bias: FloatArray
    dt: float

    @property
    def attitude(self) -> FloatArray:
        """True ``[roll, pitch]``, (N, 2), rad."""
        return np.column_stack([self.roll, self.pitch])


def _multisine(rng: np.random.Generator, t: FloatArray, band: tuple[float, float], n: int,
               scale: float, *, peak: bool) -> tuple[FloatArray, FloatArray]:
    """A sum of ``n`` sinusoids with log-uniform frequencies in ``band`` (Hz) and random phases.

    Scaled so that the peak bound (sum of amplitudes) is ``scale`` when ``peak``, else so that the
    standard deviation is ``scale``. Returns the signal and its exact time derivative.
    """
    freq = np.exp(rng.uniform(np.log(band[0]), np.log(band[1]), n))
    amp = rng.uniform(0.3, 1.0, n) / np.sqrt(freq / band[0])  # more energy at low frequency
    amp *= scale / (amp.sum() if peak else math.sqrt(0.5 * float(np.sum(amp**2))))
    phase = rng.uniform(0.0, 2.0 * math.pi, n)
    w = 2.0 * math.pi * freq
    arg = np.outer(t, w) + phase
    return np.sin(arg) @ amp, np.cos(arg) @ (amp * w)


def _band(value: object, name: str) -> tuple[float, float]:
    if not isinstance(value, (tuple, list)) or len(value) != 2:
        raise TypeError(f"{name} must be a (low, high) pair in Hz, got {value!r}")
    lo = check_number(value[0], f"{name}[0]", low=0.0, low_open=True)
    hi = check_number(value[1], f"{name}[1]", low=lo)
    return lo, hi


def imu_stream(
    seconds: float,
    rate_hz: float,
    *,
    seed: int,
    gyro_bias: tuple[float, float, float] = (0.05, -0.03, 0.02),
    gyro_noise: float = 0.005,
    accel_noise: float = 0.05,
    body_accel_std: float = 2.0,
    vertical_accel_std: float = 0.3,
    max_tilt: float = math.radians(20.0),
    attitude_band_hz: tuple[float, float] = (0.02, 0.5),
    accel_band_hz: tuple[float, float] = (0.2, 2.0),
    yaw_amplitude: float = math.pi,
    rest_seconds: float = 0.0,
    gravity: float = GRAVITY,
) -> ImuStream:
    """Simulate an IMU on a drone flying around: smooth random attitude, random accelerations.

    Roll and pitch are independent multisines bounded by ``max_tilt``; yaw a slower multisine of
    amplitude ``yaw_amplitude``. The horizontal NED accelerations (north, east) are independent
    multisines of standard deviation ``body_accel_std`` in ``accel_band_hz`` (zero mean, so the
    velocity stays bounded, like a drone manoeuvring about a spot); the vertical one has
    ``vertical_accel_std``. The attitude and the acceleration are not coupled through a thrust
    model: the point is to disturb the accelerometer's view of gravity. The truth is analytic.

    Parameters
    ----------
    seconds : float
        Duration, s, > 0.
    rate_hz : float
        Sample rate, Hz, > 0.
    seed : int
        Seed of the random trajectory and noise.
    gyro_bias : (3,) float
        Constant gyro bias ``(p, q, r)``, rad/s.
    gyro_noise : float
        White noise standard deviation per gyro sample and axis, rad/s.
    accel_noise : float
        White noise standard deviation per accelerometer sample and axis, m/s^2.
    body_accel_std : float
        Standard deviation of each horizontal NED acceleration, m/s^2.
    vertical_accel_std : float
        Standard deviation of the vertical NED acceleration, m/s^2.
    max_tilt : float
        Bound on ``|roll|`` and ``|pitch|``, rad (< pi/2).
    attitude_band_hz, accel_band_hz : (float, float)
        Frequency bands of the attitude and of the accelerations, Hz.
    yaw_amplitude : float
        Bound on ``|yaw|``, rad.
    rest_seconds : float
        Time the vehicle first sits still and level (yaw 0, as on the ground before take-off),
        s; the motion then fades in over ``RAMP_SECONDS`` (a smoothstep on the angles and the
        accelerations; the rates follow by the product rule).
    gravity : float
        Magnitude of gravity, m/s^2 (>= 0).

    Returns
    -------
    ImuStream
        ``round(seconds * rate_hz)`` samples with their exact truth.

    Raises
    ------
    TypeError, ValueError
        On a malformed argument (the message names it), or fewer than one sample.
    """
    checked = _check_imu_args(
        seconds=seconds, rate_hz=rate_hz, seed=seed, gyro_bias=gyro_bias, gyro_noise=gyro_noise,
        accel_noise=accel_noise, body_accel_std=body_accel_std,
        vertical_accel_std=vertical_accel_std, max_tilt=max_tilt,
        attitude_band_hz=attitude_band_hz, accel_band_hz=accel_band_hz,
        yaw_amplitude=yaw_amplitude, rest_seconds=rest_seconds, gravity=gravity,
    )
    return _simulate_imu(**checked)


def _check_imu_args(*, seconds: object, rate_hz: object, seed: object, gyro_bias: object,
                    gyro_noise: object, accel_noise: object, body_accel_std: object,
                    vertical_accel_std: object, max_tilt: object, attitude_band_hz: object,
                    accel_band_hz: object, yaw_amplitude: object, rest_seconds: object,
                    gravity: object) -> dict:
    """:func:`imu_stream`'s arguments checked in order (the error names the first bad one),
    as the keyword arguments of :func:`_simulate_imu`: the sample count ``n`` and period
    ``dt`` (s) replace ``seconds`` and ``rate_hz``, ``bias`` (3,) ``gyro_bias``."""
    seconds = check_number(seconds, "seconds", low=0.0, low_open=True)
    rate_hz = check_number(rate_hz, "rate_hz", low=0.0, low_open=True)
    seed = check_int(seed, "seed", low=0)
    bias = np.asarray(gyro_bias, dtype=np.float64)
    if bias.shape != (3,) or not np.all(np.isfinite(bias)):
        raise ValueError(f"gyro_bias must be 3 finite numbers (rad/s), got {gyro_bias!r}")
    checked = {
        "seed": seed,
        "bias": bias,
        "gyro_noise": check_number(gyro_noise, "gyro_noise", low=0.0),
        "accel_noise": check_number(accel_noise, "accel_noise", low=0.0),
        "body_accel_std": check_number(body_accel_std, "body_accel_std", low=0.0),
        "vertical_accel_std": check_number(vertical_accel_std, "vertical_accel_std", low=0.0),
        "max_tilt": check_number(max_tilt, "max_tilt", low=0.0, high=math.pi / 2, high_open=True),
        "yaw_amplitude": check_number(yaw_amplitude, "yaw_amplitude", low=0.0),
        "rest_seconds": check_number(rest_seconds, "rest_seconds", low=0.0),
        "gravity": check_number(gravity, "gravity", low=0.0),
        "att_band": _band(attitude_band_hz, "attitude_band_hz"),
        "acc_band": _band(accel_band_hz, "accel_band_hz"),
    }
    n = round(seconds * rate_hz)
    if n < 1:
        raise ValueError(f"seconds * rate_hz must give at least one sample, got {seconds * rate_hz}")
    return checked | {"n": n, "dt": 1.0 / rate_hz}


def _simulate_imu(*, n: int, dt: float, seed: int, bias: FloatArray, gyro_noise: float,
                  accel_noise: float, body_accel_std: float, vertical_accel_std: float,
                  max_tilt: float, att_band: tuple[float, float], acc_band: tuple[float, float],
                  yaw_amplitude: float, rest_seconds: float, gravity: float) -> ImuStream:
    """The stream of :func:`imu_stream` from its checked arguments (:func:`_check_imu_args`):
    ``n`` samples ``dt`` s apart, every random draw from ``default_rng(seed)``."""
    t = np.arange(n) * dt
    rng = np.random.default_rng(seed)
    phi, dphi = _multisine(rng, t, att_band, 8, max_tilt, peak=True)
    theta, dtheta = _multisine(rng, t, att_band, 8, max_tilt, peak=True)
    yaw_band = (att_band[0] / 2.0, att_band[1] / 2.0)
    psi, dpsi = _multisine(rng, t, yaw_band, 6, yaw_amplitude, peak=True)
    acc = np.column_stack([
        _multisine(rng, t, acc_band, 12, body_accel_std, peak=False)[0],
        _multisine(rng, t, acc_band, 12, body_accel_std, peak=False)[0],
        _multisine(rng, t, acc_band, 12, vertical_accel_std, peak=False)[0],
    ])

    if rest_seconds > 0.0:
        w, dw = _fade_in(t, rest_seconds)
        phi, dphi = w * phi, dw * phi + w * dphi
        theta, dtheta = w * theta, dw * theta + w * dtheta
        psi, dpsi = w * psi, dw * psi + w * dpsi
        acc *= w[:, None]

    rates = _body_rates(phi, theta, dphi, dtheta, dpsi)
    rot = euler_to_matrix(np.column_stack([phi, theta, psi]))  # Rz(psi) Ry(theta) Rx(phi), report eq. (2.6)
    force = np.einsum("nji,nj->ni", rot, acc - np.array([0.0, 0.0, gravity]))

    gyro = rates + bias + gyro_noise * rng.standard_normal((n, 3))
    accel = force + accel_noise * rng.standard_normal((n, 3))
    return ImuStream(t=t, roll=phi, pitch=theta, yaw=psi, body_rates=rates, accel_ned=acc,
                     specific_force=force, gyro=gyro, accel=accel, gyro_bias=bias, dt=dt)


def _fade_in(t: FloatArray, rest_seconds: float) -> tuple[FloatArray, FloatArray]:
    """Weight (N,) of the motion at times ``t`` (s) and its time derivative (1/s): 0 until
    ``rest_seconds``, then a smoothstep up to 1 over :data:`RAMP_SECONDS`."""
    x = np.clip((t - rest_seconds) / RAMP_SECONDS, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x), 6.0 * x * (1.0 - x) / RAMP_SECONDS  # smoothstep


def _body_rates(phi: FloatArray, theta: FloatArray, dphi: FloatArray, dtheta: FloatArray,
                dpsi: FloatArray) -> FloatArray:
    """Body rates ``(p, q, r)`` (N, 3), rad/s, from the Z-Y-X Euler angles (rad) and their
    time derivatives (rad/s)."""
    sp, cp, st, ct = np.sin(phi), np.cos(phi), np.sin(theta), np.cos(theta)
    return np.column_stack([  # omega = Q(lambda)^-1 lambda', inverse of report eq. (2.7)
        dphi - st * dpsi,
        cp * dtheta + sp * ct * dpsi,
        -sp * dtheta + cp * ct * dpsi,
    ])
