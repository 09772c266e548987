"""Argument checks shared by visloc's modules (every message names the argument)."""

from __future__ import annotations

import math
import numbers

__all__ = ["all_finite", "check_int", "check_real", "marker_id"]


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


def check_int(value: object, name: str, *, low: int | None = None, high: int | None = None) -> int:
    """``value`` as an int in ``[low, high]`` (``None``: unbounded), or raise naming ``name``.

    Parameters
    ----------
    value : object
        An integer (Python's or numpy's; not a bool).
    name : str
        The argument's name, for the messages.
    low, high : int or None
        Inclusive bounds.

    Returns
    -------
    int
        ``value`` as a Python int.

    Raises
    ------
    TypeError
        ``value`` is a bool or not an integer.
    ValueError
        ``value`` is outside ``[low, high]``.
    """
    if type(value) is not int:  # the common case skips the ABC checks
        if isinstance(value, bool) or not isinstance(value, numbers.Integral):
            raise TypeError(f"{name} must be an integer, got {type(value).__name__}")
        value = int(value)
    if (low is not None and value < low) or (high is not None and value > high):
        if high is None:
            raise ValueError(f"{name} must be >= {low}, got {value}")
        if low is None:
            raise ValueError(f"{name} must be <= {high}, got {value}")
        raise ValueError(f"{name} must be in [{low}, {high}], got {value}")
    return value


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
