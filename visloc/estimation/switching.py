"""The report's switching attitude estimator (report §3.1.5, eqs. 3.6-3.11).

The gyro is integrated through ``Q(lambda)`` (eq. 3.3); whenever the accelerometer seems to
measure gravity alone, the integrator is reset to the accelerometer angles. The test for
"gravity alone", in the report's accelerometer convention ``a = -f`` (``f`` the specific force,
see :mod:`visloc.estimation.attitude`)::

    a_z > 0                     (3.6)   i.e.  f_z < 0: gravity points down the body z axis
    | |a| - 9.81 | < delta_n    (3.7)   the norm is that of gravity
    | d/dt |a| |  < delta_d     (3.8)   the norm is steady (backward difference between samples)

When all three hold, ``lambda_hat = lambda_a`` and ``lambda_g = lambda_a`` (3.9-3.10); otherwise
``lambda_hat = lambda_g`` (3.11), the gyro integral.

The report found this "too naive": it crashes when the tests pass under body acceleration. The
norm of ``f = R^T (a - g e3)`` stays near ``g`` for any acceleration that keeps
``|a - g e3| = g`` (e.g. accelerating forward while sinking slightly), and it moves only to
second order in a small horizontal acceleration (``|f| ~ g + a_h^2 / 2g``), so a drone
accelerating at 1.4 m/s^2 still passes ``delta_n = 0.1`` and snaps to an angle ~8 deg wrong.
"""

from __future__ import annotations

import math

from visloc.estimation._checks import check_real
from visloc.estimation._fused import _TINY_NORM, GRAVITY, _FusedAttitude, _normalise


class SwitchingFilter(_FusedAttitude):
    """Gyro integration (re)set to the accelerometer angles when only gravity seems measured.

    Parameters
    ----------
    delta_n : float
        Bound on ``| |f| - gravity |`` (m/s^2), report eq. 3.7.
    delta_d : float
        Bound on ``| d|f|/dt |`` (m/s^3), report eq. 3.8, from the backward difference of the
        norm between consecutive usable samples. Accelerometer noise enters this difference
        amplified by ``sqrt(2) / dt``: choose it with the sample rate in mind.
    gravity : float
        ``g`` in eq. 3.7, m/s^2 (the report uses 9.81).
    initial : (roll, pitch), optional
        Initial estimate, rad; by default the first usable accelerometer sample.

    Attributes
    ----------
    roll, pitch : float
        Current estimate, rad.
    resets : int
        How many samples passed the tests (3.6-3.8) and reset the integrator.
    skipped : int
        Samples ignored (the state unchanged) because a reading was not finite. A sample at
        gimbal lock (``|cos(pitch)| < 1e-9``, where ``Q(lambda)`` is undefined) that does not
        pass the tests holds the angles without being counted here.
    """

    def __init__(self, delta_n: float, delta_d: float, *, gravity: float = GRAVITY,
                 initial: object = None) -> None:
        self.delta_n = check_real(delta_n, "delta_n", positive=True)
        self.delta_d = check_real(delta_d, "delta_d", positive=True)
        self.gravity = check_real(gravity, "gravity", positive=True)
        super().__init__(initial)
        self.resets = 0
        self._prev_norm: float | None = None

    def reset(self, roll: float, pitch: float) -> None:
        """Set the estimate (and the gyro integrator) to ``(roll, pitch)``, rad.

        The norm history used by eq. 3.8 is cleared, so the next sample cannot reset. The
        filter counts as initialised afterwards; ``resets`` and ``skipped`` are kept.

        Parameters
        ----------
        roll, pitch : float
            The estimate, rad; normalised to roll in ``[-pi, pi)``, pitch in ``[-pi/2, pi/2]``.

        Raises
        ------
        TypeError
            ``roll`` or ``pitch`` is not a real number.
        ValueError
            ``roll`` or ``pitch`` is not finite.
        """
        super().reset(roll, pitch)
        self._prev_norm = None

    def _step(self, p: float, q: float, r: float, fx: float, fy: float, fz: float,
              dt: float) -> None:
        norm = math.sqrt(fx * fx + fy * fy + fz * fz)
        prev, self._prev_norm = self._prev_norm, norm
        if not self.initialised:
            self._start(fx, fy, fz, norm)
            return
        gravity_only = (
            -fz > 0.0  # report eq. (3.6), a_z = -f_z
            and abs(norm - self.gravity) < self.delta_n  # report eq. (3.7)
            and prev is not None
            and abs(norm - prev) / dt < self.delta_d  # report eq. (3.8)
            and norm >= _TINY_NORM
        )
        if gravity_only:  # report eqs. (3.9)-(3.10): lambda_hat = lambda_g = lambda_a
            self._start(fx, fy, fz, norm)
            self.resets += 1
            return
        phi, theta = self.roll, self.pitch
        sp, cp, ct = math.sin(phi), math.cos(phi), math.cos(theta)
        if abs(ct) < 1e-9:  # gimbal lock: Q undefined (eq. 2.7), hold the angles
            return
        self.roll, self.pitch, _ = _normalise(  # report eqs. (3.3), (3.11)
            phi + dt * (p + (sp * q + cp * r) * math.sin(theta) / ct),
            theta + dt * (cp * q - sp * r))
