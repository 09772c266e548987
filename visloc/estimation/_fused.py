"""Shared plumbing of the IMU attitude filters: angle wrapping, checks, skipping, batch runs.

Conventions are documented in :mod:`visloc.estimation.attitude`.
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

GRAVITY = 9.81
_TWO_PI = 2.0 * math.pi
_TINY_NORM = 1e-6  # m/s^2: below this the accelerometer carries no direction (free fall)


def wrap_angle(angle: float) -> float:
    """Wrap an angle (rad) into ``[-pi, pi)`` (returned unchanged when already inside).

    Parameters
    ----------
    angle : float
        An angle, rad (finite).

    Returns
    -------
    float
        The same direction in ``[-pi, pi)``, rad.
    """
    if -math.pi <= angle < math.pi:
        return angle
    wrapped = (angle + math.pi) % _TWO_PI - math.pi
    return wrapped - _TWO_PI if wrapped >= math.pi else wrapped  # the modulo can round up to 2 pi


def _normalise(roll: float, pitch: float, yaw: float = 0.0) -> tuple[float, float, float]:
    """Bring Z-Y-X Euler angles to ``roll, yaw in [-pi, pi)``, ``pitch in [-pi/2, pi/2]``."""
    pitch = wrap_angle(pitch)
    if pitch > 0.5 * math.pi or pitch < -0.5 * math.pi:  # same rotation, other Euler triple
        pitch = math.copysign(math.pi, pitch) - pitch
        roll += math.pi
        yaw += math.pi
    return wrap_angle(roll), pitch, wrap_angle(yaw)


def _vec3(value: object, name: str) -> tuple[float, float, float]:
    v = as_float_array(value, name, (3,))
    return float(v[0]), float(v[1]), float(v[2])


def _initial(initial: object) -> tuple[float, float] | None:
    if initial is None:
        return None
    if not isinstance(initial, (tuple, list, np.ndarray)) or len(initial) != 2:
        raise TypeError(f"initial must be None or a (roll, pitch) pair, got {initial!r}")
    return check_real(initial[0], "initial roll"), check_real(initial[1], "initial pitch")


class _FusedAttitude:
    """Shared plumbing of the gyro + accelerometer filters (checks, skipping, batch run)."""

    def __init__(self, initial: object) -> None:
        init = _initial(initial)
        self.skipped = 0
        self.roll, self.pitch = (0.0, 0.0) if init is None else _normalise(*init)[:2]
        self.initialised = init is not None

    def reset(self, roll: float, pitch: float) -> None:
        """Set the attitude estimate to ``(roll, pitch)`` (rad); counters are kept."""
        self.roll, self.pitch = _normalise(check_real(roll, "roll"), check_real(pitch, "pitch"))[:2]
        self.initialised = True

    @property
    def attitude(self) -> FloatArray:
        """Current ``[roll, pitch]`` estimate, rad, (2,)."""
        return np.array([self.roll, self.pitch])

    def _step(self, p: float, q: float, r: float, fx: float, fy: float, fz: float,
              dt: float) -> None:
        raise NotImplementedError

    def _start(self, fx: float, fy: float, fz: float, norm: float) -> None:
        """Initialise from the first usable accelerometer sample (report eqs. 3.1-3.2)."""
        if norm >= _TINY_NORM:
            self.roll = math.atan2(-fy, -fz)
            self.pitch = math.asin(max(-1.0, min(1.0, fx / norm)))
            self.initialised = True

    def update(self, gyro: object, accel: object, dt: float) -> tuple[float, float]:
        """Process one IMU sample.

        Parameters
        ----------
        gyro : array_like (3,)
            Body rates ``(p, q, r)``, rad/s.
        accel : array_like (3,)
            Specific force in NED body axes, m/s^2 (level at rest ``(0, 0, -9.81)``).
        dt : float
            Time since the previous sample, s, > 0.

        Returns
        -------
        roll, pitch : float
            The estimate after this sample, rad. A sample with a non-finite value is skipped
            (state unchanged) and counted in ``skipped``.
        """
        dt = check_dt(dt)
        g = _vec3(gyro, "gyro")
        a = _vec3(accel, "accel")
        if all(math.isfinite(v) for v in g + a):
            self._step(*g, *a, dt)
        else:
            self.skipped += 1
        return self.roll, self.pitch

    def run(self, gyro: object, accel: object, dt: object) -> FloatArray:
        """Process a sequence sample by sample (same result as repeated :meth:`update`).

        Parameters
        ----------
        gyro, accel : array_like (N, 3)
            Body rates (rad/s) and specific forces (m/s^2).
        dt : float or array_like (N,)
            Step before each sample, s, > 0.

        Returns
        -------
        ndarray (N, 2)
            ``[roll, pitch]`` (rad) after each sample.
        """
        g = as_float_array(gyro, "gyro", (None, 3))
        a = as_float_array(accel, "accel", (len(g), 3))
        steps = check_dt_sequence(dt, len(g)).tolist()
        ok = (np.isfinite(g).all(axis=1) & np.isfinite(a).all(axis=1)).tolist()
        out = np.empty((len(g), 2))
        step = self._step
        for i, (gi, ai) in enumerate(zip(g.tolist(), a.tolist())):
            if ok[i]:
                step(gi[0], gi[1], gi[2], ai[0], ai[1], ai[2], steps[i])
            else:
                self.skipped += 1
            out[i, 0] = self.roll
            out[i, 1] = self.pitch
        return out
