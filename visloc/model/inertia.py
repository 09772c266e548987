"""Moment of inertia from a bifilar pendulum (report section 2.2.1, eq. 2.14; Appendix D).

A body of mass ``m`` hangs from two vertical cords of length ``L`` attached at a horizontal
distance ``r`` from its centre of gravity (``r`` is *half* the distance ``2 r`` between the
cords, App. D after eq. D.2). Twisting it about the vertical axis through the CoG gives, for
small angles, ``I theta'' = -(m g r^2 / L) theta`` (eq. D.8), an oscillation at
``omega = 2 pi f`` and ``I = m g r^2 / (4 pi^2 L f^2)`` (eqs. 2.14, D.13). The report writes
``f = 2 pi omega``; with ``f`` in Hz (``n`` oscillations in ``t`` seconds: ``f = n / t``, the
way its tables compute ``f``) the relation is ``omega = 2 pi f``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from visloc.types import FloatArray


def _positive(value: ArrayLike, name: str) -> FloatArray:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name}: expected real numbers, got {type(value).__name__}") from exc
    if not np.all(np.isfinite(arr)) or np.any(arr <= 0):
        raise ValueError(f"{name}: expected finite values > 0, got {arr!r}")
    return arr


def bifilar_inertia(
    m: ArrayLike, r: ArrayLike, L: ArrayLike, f: ArrayLike, *, g: float = 9.81
) -> FloatArray | float:
    """Moment of inertia about the pendulum's vertical axis, ``I = m g r^2 / (4 pi^2 L f^2)``.

    Parameters
    ----------
    m : array_like
        Mass of the body, kg.
    r : array_like
        Horizontal distance from the CoG to each cord, i.e. half the distance between the
        cords, m.
    L : array_like
        Cord length, m.
    f : array_like
        Oscillation frequency, Hz (oscillations per second).
    g : float
        Gravitational acceleration, m/s^2 (report: 9.81).

    Returns
    -------
    float or ndarray
        Moment of inertia, kg m^2 (report eqs. 2.14, D.13): a float when every input is a
        scalar, else an array of the broadcast shape.

    Raises
    ------
    TypeError
        An argument is not real numbers.
    ValueError
        An argument has a value that is not finite and > 0.
    """
    m, r, L, f = (_positive(v, n) for v, n in ((m, "m"), (r, "r"), (L, "L"), (f, "f")))
    g = float(_positive(g, "g"))
    inertia = m * g * r**2 / (4.0 * np.pi**2 * L * f**2)  # report eq. (2.14) / (D.13)
    return float(inertia) if inertia.ndim == 0 else inertia


@dataclass(frozen=True, eq=False)
class BifilarResult:
    """Moments of inertia computed from bifilar measurements.

    Attributes
    ----------
    f : ndarray (N,)
        Oscillation frequency ``n / t`` of each row, Hz.
    inertia : ndarray (N,)
        Moment of inertia of each row, kg m^2 (eq. D.13).
    mean : float
        Mean of ``inertia``, kg m^2 (how App. D and Table 2.2 combine repeated measurements).
    """

    f: FloatArray
    inertia: FloatArray
    mean: float


def inertia_from_measurements(rows: ArrayLike, *, g: float = 9.81) -> BifilarResult:
    """Moments of inertia from measured ``(m, r, L, t, n)`` rows (report Appendix D tables).

    Parameters
    ----------
    rows : array_like (N, 5) or (5,)
        Per row: mass ``m`` (kg), half the distance between the cords ``r`` (m), cord length
        ``L`` (m), time ``t`` of ``n`` oscillations (s), number of oscillations ``n``; a
        single row may be given as (5,).
    g : float
        Gravitational acceleration, m/s^2.

    Returns
    -------
    BifilarResult
        ``f = n / t`` per row (Hz), the inertia of each row and their mean (kg m^2).

    Raises
    ------
    TypeError
        ``rows`` or ``g`` not real numbers.
    ValueError
        ``rows`` not (N, 5) with N >= 1; an entry of ``rows`` or ``g`` not finite and > 0.
    """
    try:
        arr = np.asarray(rows, dtype=float)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"rows: expected (N, 5) real numbers, got {type(rows).__name__}") from exc
    if arr.ndim == 1 and arr.size == 5:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != 5 or arr.shape[0] == 0:
        raise ValueError(f"rows: expected shape (N, 5) of (m, r, L, t, n), got {arr.shape}")
    _positive(arr, "rows")
    m, r, L, t, n = arr.T
    f = n / t  # App. D nomenclature: n oscillations during measure time t
    inertia = np.atleast_1d(bifilar_inertia(m, r, L, f, g=g))
    return BifilarResult(f=f, inertia=inertia, mean=float(inertia.mean()))
