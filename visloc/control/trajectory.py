"""Smooth references from waypoints: rest-to-rest minimum-jerk segments with speed and
acceleration limits the model can fly, giving position, velocity, acceleration and jerk at any
time (issue 20; the report's plain set-point steps dip and saturate on long moves, §4.4).

A segment from ``p0`` to ``p1`` over ``T`` seconds follows ``p0 + (p1 - p0) s(t / T)`` with
``s(u) = 10 u^3 - 15 u^4 + 6 u^5``: zero velocity and acceleration at both ends, peak speed
``1.875 D / T`` and peak acceleration ``5.7735 D / T^2`` (``D = |p1 - p0|``). Each segment's
``T`` is the shortest that keeps both within the limits.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from visloc.control._checks import check_params, check_real
from visloc.model.params import ARDRONE2, ARDrone2Params
from visloc.types import FloatArray

__all__ = ["PEAK_ACCELERATION", "PEAK_SPEED", "Figure8Trajectory", "MinJerkTrajectory", "TrajectoryLimits",
           "model_limits"]

PEAK_SPEED = 1.875
"""Peak of ``s'(u)``: a segment's peak speed is ``1.875 D / T``."""
PEAK_ACCELERATION = 10.0 / math.sqrt(3.0)
"""Peak of ``|s''(u)|`` (5.7735): a segment's peak acceleration is ``5.7735 D / T^2``."""


@dataclass(frozen=True)
class TrajectoryLimits:
    """Speed and acceleration a reference may ask for.

    Attributes
    ----------
    speed : float
        m/s (> 0).
    acceleration : float
        Horizontal and vertical acceleration, m/s^2 (> 0).
    """

    speed: float
    acceleration: float

    def __post_init__(self) -> None:
        check_real(self.speed, "speed", positive=True)
        check_real(self.acceleration, "acceleration", positive=True)


def model_limits(params: ARDrone2Params = ARDRONE2, *, max_tilt_deg: float = 15.0, thrust_margin: float = 0.3,
                 speed: float = 2.0) -> TrajectoryLimits:
    """Limits the vehicle can fly: the acceleration a tilt of ``max_tilt_deg`` gives, ``g tan(tilt)``,
    and no more than the thrust margin allows, ``g sqrt((1 + margin)^2 - 1)`` (thrust up to
    ``(1 + margin) m g``, of which ``m g`` holds the height).

    Parameters
    ----------
    params : ARDrone2Params
        The vehicle (its ``g``).
    max_tilt_deg : float
        The tilt the attitude loop is trusted with, degrees (0-45): the pilot-frame
        linearisation holds to about 15-20 degrees.
    thrust_margin : float
        Thrust over hover the motors keep for the height loop and the tilt, a fraction (> 0).
    speed : float
        Speed limit, m/s (> 0).

    Returns
    -------
    TrajectoryLimits
    """
    p = check_params(params)
    tilt = check_real(max_tilt_deg, "max_tilt_deg", positive=True)
    if tilt > 45.0:
        raise ValueError(f"max_tilt_deg must be at most 45, got {tilt}")
    margin = check_real(thrust_margin, "thrust_margin", positive=True)
    a = min(p.g * math.tan(math.radians(tilt)), p.g * math.sqrt((1.0 + margin) ** 2 - 1.0))
    return TrajectoryLimits(check_real(speed, "speed", positive=True), a)


def _profile(u: float, T: float) -> tuple[float, float, float, float]:
    """The minimum-jerk profile ``s(u) = 10 u^3 - 15 u^4 + 6 u^5`` and its first three time
    derivatives at the fraction ``u`` of a move lasting ``T`` seconds."""
    return (u**3 * (10.0 - 15.0 * u + 6.0 * u * u), 30.0 * u * u * (1.0 - u) ** 2 / T,
            60.0 * u * (1.0 - u) * (1.0 - 2.0 * u) / T**2, 60.0 * (1.0 - 6.0 * u + 6.0 * u * u) / T**3)


class MinJerkTrajectory:
    """Rest-to-rest minimum-jerk segments through waypoints, as fast as the limits allow.

    Parameters
    ----------
    waypoints : array_like (N, 3)
        Positions, m (N >= 2), in the frame the controller uses (NED ``A``).
    limits : TrajectoryLimits
        Speed and acceleration limits (:func:`model_limits`).
    start : float
        Time of the first waypoint, s.
    durations : array_like (N - 1,), optional
        Each segment's duration, s; each must be at least the limits' minimum (else a
        ``ValueError`` naming the segment and its minimum).

    Attributes
    ----------
    times : ndarray (N,)
        When each waypoint is reached, s.
    end : float
        When the last is reached, s.
    """

    def __init__(self, waypoints: ArrayLike, limits: TrajectoryLimits, *, start: float = 0.0,
                 durations: ArrayLike | None = None) -> None:
        w = np.asarray(waypoints, dtype=np.float64)
        if w.ndim != 2 or w.shape[1] != 3 or len(w) < 2:
            raise ValueError(f"waypoints must be (N >= 2, 3), got shape {w.shape}")
        if not np.isfinite(w).all():
            raise ValueError("waypoints must be finite")
        if not isinstance(limits, TrajectoryLimits):
            raise TypeError(f"limits: expected TrajectoryLimits, got {type(limits).__name__}")
        t0 = check_real(start, "start")
        dist = np.linalg.norm(np.diff(w, axis=0), axis=1)
        shortest = np.maximum(PEAK_SPEED * dist / limits.speed, np.sqrt(PEAK_ACCELERATION * dist / limits.acceleration))
        if durations is None:
            T = shortest
        else:
            T = np.asarray(durations, dtype=np.float64).reshape(-1)
            if T.shape != dist.shape or not np.isfinite(T).all() or (T <= 0).any():
                raise ValueError(f"durations must be {len(dist)} positive finite seconds, got {T.tolist()}")
            short = np.flatnonzero(T < shortest * (1 - 1e-9))
            if len(short):
                k = int(short[0])
                raise ValueError(f"segment {k} ({dist[k]:.3g} m) needs at least {shortest[k]:.3g} s within the limits "
                                 f"(speed {limits.speed:g} m/s, acceleration {limits.acceleration:.3g} m/s^2), "
                                 f"got {T[k]:.3g} s")
        self.waypoints, self.limits = w, limits
        self.durations = T
        self.times = t0 + np.concatenate([[0.0], np.cumsum(T)])
        self.end = float(self.times[-1])

    def sample(self, t: float) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Position, velocity, acceleration and jerk (3,) each at time ``t`` (before the start:
        the first waypoint at rest; after the end: the last).

        Parameters
        ----------
        t : float
            Time, s.

        Returns
        -------
        tuple of 4 ndarrays (3,)
            m, m/s, m/s^2, m/s^3.
        """
        zero = np.zeros(3)
        if t <= self.times[0]:
            return self.waypoints[0].copy(), zero, zero.copy(), zero.copy()
        if t >= self.end:
            return self.waypoints[-1].copy(), zero, zero.copy(), zero.copy()
        k = int(np.searchsorted(self.times, t, side="right") - 1)
        T = self.durations[k]
        if T <= 0:
            return self.waypoints[k + 1].copy(), zero, zero.copy(), zero.copy()
        s, ds, dds, ddds = _profile((t - self.times[k]) / T, T)
        d = self.waypoints[k + 1] - self.waypoints[k]
        return self.waypoints[k] + s * d, ds * d, dds * d, ddds * d


class Figure8Trajectory:
    """A figure eight (Gerono's lemniscate) in the horizontal plane, flown once from rest to
    rest: ``p(t) = centre + (w/2 sin s, w/4 sin 2s, 0)`` with the phase ``s`` going from 0 to
    ``2 pi`` along the minimum-jerk profile of :class:`MinJerkTrajectory` over the shortest
    duration the limits allow (found by sampling the curve's speed and acceleration).

    Parameters
    ----------
    centre : array_like (3,)
        Where the two loops cross (start and end), m.
    width : float
        Extent along x, m (> 0); the eight is half as wide along y.
    limits : TrajectoryLimits
        Speed and acceleration limits.
    start : float
        Start time, s.

    Attributes
    ----------
    duration, end : float
        s.
    """

    def __init__(self, centre: ArrayLike, width: float, limits: TrajectoryLimits, *, start: float = 0.0) -> None:
        c = np.asarray(centre, dtype=np.float64).reshape(-1)
        if c.shape != (3,) or not np.isfinite(c).all():
            raise ValueError(f"centre must be 3 finite numbers, got {np.asarray(centre).tolist()}")
        if not isinstance(limits, TrajectoryLimits):
            raise TypeError(f"limits: expected TrajectoryLimits, got {type(limits).__name__}")
        self.centre, self.width, self.limits = c, check_real(width, "width", positive=True), limits
        self.start = check_real(start, "start")
        # speed and acceleration scale as 1/T and 1/T^2: one sampling at T = 1 fixes the shortest T
        at_1s = [self._at(float(u), 1.0) for u in np.linspace(0.0, 1.0, 2001)]
        v1 = max(float(np.linalg.norm(s[1])) for s in at_1s)
        a1 = max(float(np.linalg.norm(s[2])) for s in at_1s)
        self.duration = max(v1 / limits.speed, math.sqrt(a1 / limits.acceleration))
        self.end = self.start + self.duration

    def _at(self, u: float, T: float) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Position and its first three time derivatives at the fraction ``u`` of a flight of ``T`` s."""
        s, ds, dds, ddds = (2.0 * math.pi * v for v in _profile(u, T))  # the phase, 0 .. 2 pi
        a, b = 0.5 * self.width, 0.25 * self.width
        # the curve's derivatives with respect to the phase s
        c1 = np.array([a * math.cos(s), 2 * b * math.cos(2 * s), 0.0])
        c2 = np.array([-a * math.sin(s), -4 * b * math.sin(2 * s), 0.0])
        c3 = np.array([-a * math.cos(s), -8 * b * math.cos(2 * s), 0.0])
        p = self.centre + np.array([a * math.sin(s), b * math.sin(2 * s), 0.0])
        return (p, c1 * ds, c2 * ds * ds + c1 * dds, c3 * ds**3 + 3.0 * c2 * ds * dds + c1 * ddds)

    def sample(self, t: float) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """As :meth:`MinJerkTrajectory.sample` (at rest at the centre before the start and after
        the end).

        Parameters
        ----------
        t : float
            Time, s, on the clock of ``start``.

        Returns
        -------
        tuple of 4 ndarrays (3,)
            Position, velocity, acceleration and jerk: m, m/s, m/s^2, m/s^3, in the frame of
            ``centre`` (z constant: the eight is flown level).
        """
        u = min(1.0, max(0.0, (t - self.start) / self.duration))
        if u in (0.0, 1.0):
            zero = np.zeros(3)
            return self.centre.copy(), zero, zero.copy(), zero.copy()
        return self._at(u, self.duration)
