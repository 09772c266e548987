"""Height above ground from the AR.Drone 2.0 ultrasound sensor (report §3.2.1, eqs. 3.12-3.13).

Sign mapping. The report works with the NED *depth* ``z`` (down positive, so a drone above the
ground has ``z < 0``); visloc's API returns the *height* ``h = -z`` (m, up positive). The
report's sensor model (eq. 3.12) is piecewise linear in the depth::

    u_sens = 0                    z < c_z          (too high: beyond the largest depth)
    u_sens = (z - b_z) / a_z      c_z <= z < b_z   (measurable)
    u_sens = 0                    b_z <= z         (too low: inside the smallest depth)

with ``b_z = -0.2 m`` (smallest measurable depth, i.e. 0.2 m above ground), ``c_z = -2.75 m``
(largest, 2.75 m above ground) and ``a_z = -0.0076 m`` per sensor unit. In heights:
``u_sens = (h - 0.2) / 0.0076`` for ``0.2 < h <= 2.75`` (``u_sens`` up to about 335.5), and
0 in both blind zones. The inverse (eq. 3.13) is ``z = a_h u_sens + b_h`` with ``a_h = a_z``,
``b_h = b_z``, and ``z = b`` for ``u_sens = 0``: a zero reading is ambiguous, and the report
assumes low flight, so it means the lower blind zone; visloc reports ``h = -b`` there (default
``b = b_z``, 0.2 m) with ``valid = False``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from visloc.estimation._checks import FloatArray, check_real

#: Report §3.2.1: sensor scale (m of depth per sensor unit), NED sign.
A_Z = -0.0076
#: Report §3.2.1: smallest measurable depth (m, NED; 0.2 m above ground).
B_Z = -0.2
#: Report §3.2.1: largest measurable depth (m, NED; 2.75 m above ground).
C_Z = -2.75


@dataclass(frozen=True, eq=False)
class HeightEstimate:
    """Heights from ultrasound readings.

    Attributes
    ----------
    height : float or ndarray
        Height above ground, m, up positive (``-z`` of the report's NED depth); never NaN.
    valid : bool or ndarray of bool
        True where the reading lies in the measurable range ``0 < u_sens <= u_max``; False in
        the blind zones (reading 0), for negative, too-large or non-finite readings.
    """

    height: float | FloatArray
    valid: bool | np.ndarray


def _model(a_z: float, b_z: float, c_z: float) -> tuple[float, float, float]:
    a_z = check_real(a_z, "a_z")
    b_z = check_real(b_z, "b_z")
    c_z = check_real(c_z, "c_z")
    if a_z >= 0.0:
        raise ValueError(f"a_z must be < 0 (NED: depth decreases as the reading grows), got {a_z}")
    if not c_z < b_z:
        raise ValueError(f"c_z must be below b_z (c_z < b_z, NED depths), got c_z={c_z}, b_z={b_z}")
    return a_z, b_z, c_z


def ultrasound_reading(height: object, *, a_z: float = A_Z, b_z: float = B_Z,
                       c_z: float = C_Z) -> float | FloatArray:
    """The sensor output for a true height: the report's model, eq. 3.12.

    Parameters
    ----------
    height : float or array_like
        Height above ground, m, up positive (depth ``z = -height``). Must be finite.
    a_z, b_z, c_z : float
        The report's scale (m/unit) and smallest / largest measurable depths (m), NED signs.

    Returns
    -------
    float or ndarray
        ``u_sens`` (sensor units), 0 in the blind zones ``z >= b_z`` and ``z < c_z``.
    """
    a_z, b_z, c_z = _model(a_z, b_z, c_z)
    try:
        h = np.asarray(height, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"height must be numbers, got {type(height).__name__}") from exc
    if not np.all(np.isfinite(h)):
        raise ValueError("height must be finite")
    z = -h  # NED depth
    u = np.where((c_z <= z) & (z < b_z), (z - b_z) / a_z, 0.0)  # report eq. (3.12)
    return float(u) if u.ndim == 0 else u


def ultrasound_height(u_sens: object, *, a_h: float = A_Z, b_h: float = B_Z, b: float = B_Z,
                      c_z: float = C_Z) -> HeightEstimate:
    """Height above ground from ultrasound readings: the report's map, eq. 3.13.

    ``z = a_h u_sens + b_h`` for readings in ``(0, u_max]``, ``u_max = (c_z - b_h) / a_h``
    (about 335.5 with the report's values), and ``z = b`` for ``u_sens = 0`` (low flight
    assumed); the height is ``-z``.

    Parameters
    ----------
    u_sens : float or array_like
        Sensor readings (units of the sensor). NaN/inf readings give ``valid = False``.
    a_h : float
        Depth per sensor unit, m, NED sign (the report's ``a_z = -0.0076``).
    b_h : float
        Depth at reading 0+, m, NED (the report's ``b_z = -0.2``).
    b : float
        Depth returned for a zero reading (blind zone), m, NED; default ``b_z`` (0.2 m height).
    c_z : float
        Largest measurable depth, m, NED (``-2.75``): readings above ``u_max`` are invalid and
        clipped to ``-c_z``.

    Returns
    -------
    HeightEstimate
        ``height`` (m, up positive; scalars for a scalar input) and ``valid``. Invalid readings
        give ``-b`` (zero, negative or non-finite readings) or ``-c_z`` (too large).
    """
    a_h, b_h, c_z = _model(a_h, b_h, c_z)
    b = check_real(b, "b")
    try:
        u = np.asarray(u_sens, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"u_sens must be numbers, got {type(u_sens).__name__}") from exc
    u_max = (c_z - b_h) / a_h
    finite = np.isfinite(u)
    uf = np.where(finite, u, 0.0)
    valid = finite & (uf > 0.0) & (uf <= u_max)
    z = np.where(valid, a_h * uf + b_h, b)  # report eq. (3.13)
    z = np.where(finite & (uf > u_max), c_z, z)
    if z.ndim == 0:
        return HeightEstimate(height=float(-z), valid=bool(valid))
    return HeightEstimate(height=-z, valid=valid)
