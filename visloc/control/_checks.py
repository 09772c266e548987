"""Argument checks shared by the control modules (every message names the argument);
:func:`visloc._checks.check_real` and :func:`visloc.model.params.check_params` re-exported."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from visloc._checks import all_finite, check_real
from visloc.model.params import ARDrone2Params, check_params
from visloc.types import FloatArray

__all__ = ["DEFAULT_ARM", "as_array", "check_params", "check_real", "resolve_arm"]

DEFAULT_ARM = 0.125
"""Arm distance ``d`` of eq. (2.12) used when ``params.arm`` is unset, m (see :func:`resolve_arm`)."""


def as_array(value: ArrayLike, name: str, shape: tuple[int, ...]) -> FloatArray:
    """Return ``value`` as a finite float64 array of exactly ``shape`` or raise naming it.

    Parameters
    ----------
    value : array_like
        The values to check, in any unit (returned unchanged).
    name : str
        The argument's name, for the error messages.
    shape : tuple of int
        The exact shape expected.

    Returns
    -------
    ndarray, float64, shape ``shape``
        ``value`` as an array: ``value`` itself when it already is a float64 array of that
        shape (no copy), else a new array.

    Raises
    ------
    TypeError
        ``value`` cannot be converted to real numbers.
    ValueError
        Its shape is not ``shape`` or it has a NaN or infinite entry.
    """
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name}: expected real numbers, got {type(value).__name__}") from exc
    if arr.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, got {arr.shape}")
    if not all_finite(arr):
        raise ValueError(f"{name}: expected finite values, got {arr!r}")
    return arr


def resolve_arm(params: ARDrone2Params, arm: float | None = None) -> float:
    """The arm distance ``d`` of eq. (2.12) to use, m.

    The report never prints ``d`` (section 2.1: "the distance from the motor center to the
    body frame axis, not the diagonal distance"), so ``arm`` falls back on ``params.arm`` and
    then on :data:`DEFAULT_ARM` = 0.125 m. That default is an estimate, not a
    measurement: the AR.Drone 2.0 is about 0.45 m across its rotor tips along a body axis
    with rotors of about 0.20 m diameter, which puts the motor centres about 0.25 m apart,
    i.e. 0.125 m from each body axis (about 0.18 m along the diagonal). The state-feedback
    gains do not depend on it (they are designed on ``u = [T, tau]``), and neither do the
    robustness results: the arm only scales the cross-coupling between the thrust/yaw inputs
    and the roll/pitch torques in ``Gamma(delta) Gamma_bar^-1``, which a diagonal scaling
    of the (decoupled) height and yaw states undoes, so the vertex spectra and the
    existence of a common Lyapunov matrix are the same for every ``d``. It matters for the
    pwm commands (:meth:`visloc.control.Controller.pwm`) and motor saturation.

    Parameters
    ----------
    params : ARDrone2Params
        Vehicle parameters; ``params.arm`` (m) is used when ``arm`` is None.
    arm : float, optional
        Arm distance, m (> 0). None: ``params.arm``, or :data:`DEFAULT_ARM` when that is
        None too.

    Returns
    -------
    float
        The arm distance, m.

    Raises
    ------
    TypeError
        The chosen arm distance is not a real number.
    ValueError
        It is not finite or not > 0.
    """
    if arm is None:
        arm = params.arm if params.arm is not None else DEFAULT_ARM
    return check_real(arm, "arm", positive=True)
