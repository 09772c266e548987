"""Argument checks shared by visloc's modules (every message names the argument)."""

from __future__ import annotations

import math
import numbers

__all__ = ["check_real"]


def check_real(value: object, name: str, *, positive: bool = False, nonneg: bool = False,
               allow_inf: bool = False) -> float:
    """Return ``value`` as a float, or raise naming ``name``.

    Parameters
    ----------
    value : object
        A real number (``bool`` is refused).
    name : str
        The argument's name, for the message.
    positive, nonneg : bool
        Require ``> 0`` or ``>= 0``.
    allow_inf : bool
        Accept ``+inf`` as well as finite values.

    Raises
    ------
    TypeError
        ``value`` is not a real number.
    ValueError
        It is NaN, infinite (unless allowed) or breaks ``positive`` / ``nonneg``.
    """
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
    v = float(value)
    if not (math.isfinite(v) or (allow_inf and v == math.inf)):
        raise ValueError(f"{name} must be finite, got {v!r}")
    if positive and v <= 0.0:
        raise ValueError(f"{name} must be > 0, got {v!r}")
    if nonneg and v < 0.0:
        raise ValueError(f"{name} must be >= 0, got {v!r}")
    return v
