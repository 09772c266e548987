"""Argument checks shared by the estimation modules (every message names the argument);
:func:`visloc._checks.check_real` re-exported."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from visloc._checks import check_real

FloatArray = NDArray[np.float64]

__all__ = ["FloatArray", "as_float_array", "check_dt", "check_dt_sequence", "check_real"]


def check_dt(dt: object, name: str = "dt") -> float:
    """Return a time step as a finite float > 0 (s) or raise naming ``name``."""
    return check_real(dt, name, positive=True)


def as_float_array(value: object, name: str, shape: tuple[int | None, ...]) -> FloatArray:
    """Return ``value`` as a float64 array of ``shape`` (``None`` = any length).

    Non-finite entries are allowed here; callers decide whether to skip or reject them.
    """
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be an array of numbers, got {type(value).__name__}") from exc
    if arr.shape == shape:  # the usual call, at once
        return arr
    if arr.ndim != len(shape) or any(s is not None and s != n for s, n in zip(shape, arr.shape)):
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name} must have shape {want}, got {arr.shape}")
    return arr


def check_dt_sequence(dt: object, n: int, name: str = "dt") -> FloatArray:
    """Return ``dt`` (a number or an (n,) array, s) as an (n,) array of finite steps > 0."""
    if np.ndim(dt) == 0:
        return np.full(n, check_dt(dt, name))  # type: ignore[arg-type]
    arr = as_float_array(dt, name, (n,))
    bad = ~(np.isfinite(arr) & (arr > 0.0))
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"{name} must be finite and > 0 at every sample, got {arr[i]} at index {i}")
    return arr
