"""Argument checks shared by visloc's modules (every message names the argument)."""

from __future__ import annotations

import math
import numbers

__all__ = ["all_finite", "check_real", "marker_id"]


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
    if type(value) is float:  # the common case, without the ABC check below
        v = value
    elif isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
    else:
        v = float(value)
    if not (math.isfinite(v) or (allow_inf and v == math.inf)):
        raise ValueError(f"{name} must be finite, got {v!r}")
    if positive and v <= 0.0:
        raise ValueError(f"{name} must be > 0, got {v!r}")
    if nonneg and v < 0.0:
        raise ValueError(f"{name} must be >= 0, got {v!r}")
    return v


def all_finite(arr: object) -> bool:
    """``bool(np.isfinite(arr).all())`` for a float array, several times faster on the few
    values of a state or a command (Python's ``math.isfinite`` on each, same answer).

    Parameters
    ----------
    arr : ndarray
        A float array of any shape.

    Returns
    -------
    bool
        No NaN and no infinity in ``arr``.
    """
    if arr.size <= 64:  # type: ignore[attr-defined]
        return all(map(math.isfinite, arr.ravel().tolist()))  # type: ignore[attr-defined]
    import numpy as np  # (this module itself loads no numpy)

    return bool(np.isfinite(arr).all())


def marker_id(value: object, where: str) -> int:
    """A marker id as an int: a whole number (an integer, or a float with no fraction), or
    raise naming ``where``.

    Parameters
    ----------
    value : object
        The id.
    where : str
        Where it came from, for the message (e.g. ``"expected"``).

    Returns
    -------
    int

    Raises
    ------
    TypeError
        ``value`` is a bool or not a real number.
    ValueError
        ``value`` has a fraction or is not finite (no id is rounded into another).
    """
    if type(value) is int:  # the common case, without the ABC checks below
        return value
    if isinstance(value, numbers.Integral) and not isinstance(value, bool):
        return int(value)
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{where}: marker ids must be whole numbers, got {value!r}")
    if not (math.isfinite(value) and float(value).is_integer()):
        raise ValueError(f"{where}: marker ids must be whole numbers, got {value!r}")
    return int(value)
