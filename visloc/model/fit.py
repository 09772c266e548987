"""Weighted least-squares fit of the propulsion model (report Appendix E, eqs. E.1-E.12).

The model ``T_mi = c_mi (pwm + k)^2``, ``tau_mi = d_mi (pwm + k)^2`` (E.1-E.2) is rewritten as
``pwm = a_mi sqrt(T_mi) - k`` and ``pwm = b_mi sqrt(tau_mi) - k`` (E.3-E.4) with
``a_mi = 1 / sqrt(c_mi)`` and ``b_mi = 1 / sqrt(d_mi)``, which is linear in
``x = [a_m1 .. a_mI, b_m1 .. b_mJ, k]`` (E.10) and solved as ``x = (A^T W A)^-1 A^T W b``
(E.8). The residuals are therefore in pwm percent, not in newtons.

The report writes both ``W A x = W b`` (E.7) and the normal equations (E.8); they agree only if
``W`` holds the square roots of the weights. This module follows (E.8): ``weights`` are the
diagonal of ``W`` in the normal equations.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from visloc.types import FloatArray

REPORT_PWM_GRID: FloatArray = np.arange(10.0, 101.0, 10.0)
"""The measured commands 10 %, 20 %, ..., 100 % (report section 2.2.2)."""

REPORT_WEIGHTS: FloatArray = np.array([1, 1, 1, 5, 5, 50, 100, 100, 50, 1], dtype=float)
"""Weights ``w`` of eq. (E.12), one per command of :data:`REPORT_PWM_GRID` (large near hover)."""


@dataclass(frozen=True, eq=False)
class PropulsionFit:
    """Result of :func:`fit_propulsion`.

    Attributes
    ----------
    a : ndarray (M,)
        ``a_mi = 1 / sqrt(c_mi)`` of each thrust-measured motor, % / sqrt(N) (eq. E.3).
    b : ndarray (J,)
        ``b_mi = 1 / sqrt(d_mi)`` of each torque-measured motor, % / sqrt(N m) (eq. E.4).
    k : float
        Shared pwm shift, percent.
    c : ndarray (M,)
        Thrust coefficients ``1 / a^2``, N/%^2.
    d : ndarray (J,)
        Torque coefficients ``1 / b^2``, N m/%^2.
    rms_thrust : float
        Unweighted RMS of the thrust rows' residuals ``a sqrt(T) - k - pwm``, percent.
    rms_torque : float
        The same for the torque rows (NaN without torque data), percent.
    n_samples : int
        Number of measurements used (finite entries of ``thrust`` and ``torque``).
    """

    a: FloatArray
    b: FloatArray
    k: float
    c: FloatArray
    d: FloatArray
    rms_thrust: float
    rms_torque: float
    n_samples: int


def _matrix(value: ArrayLike, name: str, n: int) -> FloatArray:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name}: expected real numbers, got {type(value).__name__}") from exc
    if arr.ndim == 1:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != n:
        raise ValueError(f"{name}: expected shape (motors, {n}) or ({n},), got {arr.shape}")
    if np.any(np.isinf(arr)):
        raise ValueError(f"{name}: expected finite values or NaN for missing ones")
    if np.any(arr[np.isfinite(arr)] < 0):
        raise ValueError(f"{name}: expected values >= 0 (use the magnitude of the torque)")
    return arr


def _pwm(pwm: ArrayLike) -> FloatArray:
    """``pwm`` as a float array (N,), N >= 2, of finite commands > 0 %; else TypeError/ValueError."""
    try:
        p = np.asarray(pwm, dtype=float)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"pwm: expected real numbers, got {type(pwm).__name__}") from exc
    if p.ndim != 1 or p.size < 2:
        raise ValueError(f"pwm: expected shape (N,) with N >= 2, got {p.shape}")
    if not np.all(np.isfinite(p)) or np.any(p <= 0):
        raise ValueError("pwm: expected finite commands > 0 % (the model holds for pwm > 0)")
    return p


def _weights(weights: ArrayLike | None, n: int) -> FloatArray:
    """The weights (n,) of the normal equations (E.8): ``weights`` checked (finite, >= 0), or
    the report's :data:`REPORT_WEIGHTS` (E.12) when None (then n must be 10)."""
    if weights is None:
        if n != REPORT_WEIGHTS.size:
            raise ValueError(
                f"weights: the report's default (E.12) has {REPORT_WEIGHTS.size} entries for "
                f"pwm 10, 20, ..., 100 %; got N = {n} commands, pass weights explicitly"
            )
        return REPORT_WEIGHTS
    w = np.asarray(weights, dtype=float)
    if w.shape != (n,):
        raise ValueError(f"weights: expected shape ({n},), got {w.shape}")
    if not np.all(np.isfinite(w)) or np.any(w < 0):
        raise ValueError("weights: expected finite values >= 0")
    return w


def _system(
    p: FloatArray, t: FloatArray, q: FloatArray, w: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, np.ndarray]:
    """The linear system of eqs. (E.9)-(E.11) over the finite samples of thrust ``t`` (M, N)
    and torque ``q`` (J, N): ``A`` (S, M + J + 1), ``b`` (S,) in pwm percent, the samples'
    weights (S,) and a boolean mask (S,) of the thrust rows."""
    m = t.shape[0]
    cols = m + q.shape[0] + 1
    rows_a, rows_b, rows_w, is_thrust = [], [], [], []
    for block, offset in ((t, 0), (q, m)):
        for i, series in enumerate(block):
            ok = np.isfinite(series)
            row = np.zeros((int(ok.sum()), cols))
            row[:, offset + i] = np.sqrt(series[ok])  # report eq. (E.9): sqrt(T) or sqrt(tau)
            row[:, -1] = -1.0  # report eq. (E.9): last column -1 for k
            rows_a.append(row)
            rows_b.append(p[ok])  # report eq. (E.11)
            rows_w.append(w[ok])
            is_thrust.append(np.full(row.shape[0], offset == 0))
    return np.vstack(rows_a), np.concatenate(rows_b), np.concatenate(rows_w), np.concatenate(is_thrust)


def fit_propulsion(
    pwm: ArrayLike,
    thrust: ArrayLike,
    torque: ArrayLike | None = None,
    *,
    weights: ArrayLike | None = None,
) -> PropulsionFit:
    """Fit per-motor ``c_i``, ``d_i`` and the shared shift ``k`` (report Appendix E).

    Parameters
    ----------
    pwm : array_like (N,)
        Commands at which every motor was measured, percent, all > 0.
    thrust : array_like (M, N) or (N,)
        Static thrust of M motors, N; NaN marks a missing measurement.
    torque : array_like (J, N) or (N,), optional
        Magnitude of the static torque of J motors (any subset of motors), N m; NaN = missing.
    weights : array_like (N,), optional
        Weight of each command in the normal equations (E.8). Default: the report's
        :data:`REPORT_WEIGHTS` (E.12), which requires the report's 10-command grid.

    Returns
    -------
    PropulsionFit
        ``c`` (M,) in N/%^2, ``d`` (J,) in N m/%^2, the shared ``k`` in percent, with the fit's
        ``a, b`` and RMS residuals (percent).

    Raises
    ------
    ValueError
        On bad shapes, non-positive commands, negative measurements or negative weights, or
        when the data do not determine every parameter (a motor with fewer than two samples).
    TypeError
        ``pwm``, ``thrust`` or ``torque`` not real numbers.
    """
    p = _pwm(pwm)
    n = p.size
    t = _matrix(thrust, "thrust", n)
    if not len(t):
        raise ValueError(f"thrust: expected at least one motor's measurements, got shape {t.shape}")
    q = np.empty((0, n)) if torque is None else _matrix(torque, "torque", n)
    w = _weights(weights, n)

    m, j = t.shape[0], q.shape[0]
    a_mat, b_vec, w_vec, thrust_rows = _system(p, t, q, w)
    sw = np.sqrt(w_vec)
    # report eq. (E.8): x = (A^T W A)^-1 A^T W b, solved as lstsq(sqrt(W) A, sqrt(W) b)
    x, _, rank, _ = np.linalg.lstsq(a_mat * sw[:, None], b_vec * sw, rcond=None)
    if rank < a_mat.shape[1]:  # m + j + 1 parameters
        raise ValueError(
            "thrust, torque: the data do not determine every parameter (each motor needs at "
            "least two measurements with non-zero weight)"
        )
    if np.any(x[:-1] <= 0):
        raise ValueError("thrust, torque: the fit gave a non-positive a_i or b_i; check the data")
    res = a_mat @ x - b_vec
    rms_t = float(np.sqrt(np.mean(res[thrust_rows] ** 2)))
    rms_q = float(np.sqrt(np.mean(res[~thrust_rows] ** 2))) if j else float("nan")
    a, b = x[:m], x[m:m + j]
    return PropulsionFit(
        a=a,
        b=b,
        k=float(x[-1]),
        c=1.0 / a**2,  # report: a_mi = sqrt(1 / c_mi)
        d=1.0 / b**2,  # report: b_mi = sqrt(1 / d_mi)
        rms_thrust=rms_t,
        rms_torque=rms_q,
        n_samples=int(b_vec.size),
    )


def mean_std(values: ArrayLike, *, ddof: int = 1) -> tuple[float, float]:
    """Mean and standard deviation of coefficients, ignoring NaN (missing) entries.

    Parameters
    ----------
    values : array_like
        Coefficients, e.g. the ``c_i`` of Table E.1 (any unit).
    ddof : int
        Delta degrees of freedom of the standard deviation; 1 (the sample standard deviation)
        is what reproduces the report's ``d`` row of Table E.1.

    Returns
    -------
    mean, std : float
        Mean and standard deviation in the unit of ``values``.

    Raises
    ------
    ValueError
        Not more than ``ddof`` non-NaN entries.
    """
    v = np.asarray(values, dtype=float).ravel()
    v = v[~np.isnan(v)]
    if v.size <= ddof:
        raise ValueError(f"values: expected more than ddof={ddof} non-NaN entries, got {v.size}")
    return float(v.mean()), float(v.std(ddof=ddof))
