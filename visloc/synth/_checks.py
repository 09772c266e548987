"""Argument checks shared by the synthetic renderers (messages name the argument)."""

from __future__ import annotations

import numbers

import numpy as np
from numpy.typing import NDArray


def check_camera(K: object) -> NDArray[np.float64]:
    """Return ``K`` as a pinhole camera matrix or raise naming ``K``.

    Parameters
    ----------
    K : array_like (3, 3)
        Camera matrix ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]``, px.

    Returns
    -------
    ndarray (3, 3) float64
        A new array.

    Raises
    ------
    TypeError
        If ``K`` is not an array of numbers.
    ValueError
        If it is not (3, 3), not finite, or has ``fx <= 0``, ``fy <= 0`` or a last row other
        than ``[0, 0, 1]``.
    """
    try:
        k = np.array(K, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"K must be a (3, 3) array of numbers, got {type(K).__name__}") from exc
    if k.shape != (3, 3):
        raise ValueError(f"K must have shape (3, 3), got {k.shape}")
    if not np.all(np.isfinite(k)):
        raise ValueError("K must be finite")
    a, b, c = k[2].tolist()  # np.allclose(k[2], [0, 0, 1])'s test, without its 30 us
    if k[0, 0] <= 0 or k[1, 1] <= 0 or not (abs(a) <= 1e-8 and abs(b) <= 1e-8 and abs(c - 1.0) <= 1e-8 + 1e-5):
        raise ValueError(f"K must have fx > 0, fy > 0 and last row [0, 0, 1], got {k.tolist()}")
    return k


def check_size(size: object) -> tuple[int, int]:
    """Return ``size`` as ``(width, height)`` ints or raise naming ``size``.

    Parameters
    ----------
    size : (int, int)
        ``(width, height)`` of an image, px, each >= 8 (a tuple or list).

    Returns
    -------
    (int, int)
        ``(width, height)``.

    Raises
    ------
    TypeError
        If ``size`` is not a pair of ints.
    ValueError
        If a side is below 8 px.
    """
    if not isinstance(size, (tuple, list)) or len(size) != 2:
        raise TypeError(f"size must be a (width, height) pair, got {size!r}")
    if not all(isinstance(v, numbers.Integral) and not isinstance(v, bool) for v in size):
        raise TypeError(f"size must hold two ints, got {size!r}")
    w, h = int(size[0]), int(size[1])
    if w < 8 or h < 8:
        raise ValueError(f"size must be at least (8, 8), got {(w, h)}")
    return w, h


def check_number(
    value: object,
    name: str,
    *,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
    high_open: bool = False,
) -> float:
    """Return ``value`` as a finite float in the given range or raise naming ``name``.

    Parameters
    ----------
    value : float
        The number to check (a real number, not a bool).
    name : str
        Name of the argument in error messages.
    low, high : float or None
        Bounds of the range (``None``: unbounded).
    low_open, high_open : bool
        Exclude the bound itself.

    Returns
    -------
    float

    Raises
    ------
    TypeError
        If ``value`` is not a real number.
    ValueError
        If it is not finite or out of the range.
    """
    if not isinstance(value, numbers.Real) or isinstance(value, bool):
        raise TypeError(f"{name} must be a number, got {type(value).__name__}")
    v = float(value)
    if not np.isfinite(v):
        raise ValueError(f"{name} must be finite, got {v}")
    if low is not None and (v < low or (low_open and v == low)):
        raise ValueError(f"{name} must be {'>' if low_open else '>='} {low}, got {v}")
    if high is not None and (v > high or (high_open and v == high)):
        raise ValueError(f"{name} must be {'<' if high_open else '<='} {high}, got {v}")
    return v


def check_rng(rng: object, *, allow_none: bool = True) -> np.random.Generator:
    """``rng`` as a numpy Generator: a Generator itself, a seed (an int >= 0) or, with
    ``allow_none``, None (fresh entropy).

    Raises
    ------
    TypeError
        Anything else (a bool or a float seed too); the message names ``rng``.
    ValueError
        A negative seed (numpy's own message did not name the argument).
    """
    if isinstance(rng, np.random.Generator) or (rng is None and allow_none):
        return np.random.default_rng(rng)
    if isinstance(rng, bool) or not isinstance(rng, (int, np.integer)):
        what = "a numpy Generator, an int seed or None" if allow_none else "a numpy Generator or an int seed"
        raise TypeError(f"rng must be {what}, got {type(rng).__name__}")
    if rng < 0:
        raise ValueError(f"rng: a seed must be an integer >= 0, got {rng}")
    return np.random.default_rng(int(rng))
