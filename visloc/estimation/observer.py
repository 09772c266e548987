"""Luenberger observer for position-measured, velocity-estimated motion (report eq. 3.14).

Per horizontal axis the model is a double integrator, state ``[position, velocity]``::

    A = [[0, 1],      C = [1, 0]      (continuous time, eq. 3.14)
         [0, 0]]

with the position measured (e.g. by the external top camera) and the velocity estimated. The
gains come from pole placement. ``scipy.signal.place_poles`` refuses to place a pole more often
than ``rank(B)`` (here 1), so a critically damped observer (a repeated pole such as
``(-3, -3)``) fails there; :func:`ackermann_observer_gain` implements Ackermann's formula,
``L = phi(A) O^-1 e_n``, which has no such limit.

Discrete time. With step ``dt`` the exact (zero-order-hold) discretisation is
``F = expm(A dt) = [[1, dt], [0, 1]]``; since ``A^2 = 0`` it coincides with forward Euler.
Two observer forms are supported:

- ``"predictor"``: ``x_{k+1} = F x_k + L (z_k - C x_k)``; error matrix ``F - L C``.
- ``"current"``: ``x_k^- = F x_{k-1}``, ``x_k = x_k^- + L (z_k - C x_k^-)``; error matrix
  ``(I - L C) F = F - L C F`` (uses the newest measurement; :class:`LuenbergerObserver`).
"""

from __future__ import annotations

import math

import numpy as np

from visloc.estimation._checks import FloatArray, as_float_array, check_dt

_A = np.array([[0.0, 1.0], [0.0, 0.0]])
_C = np.array([[1.0, 0.0]])


def _char_poly(poles: object, n: int) -> FloatArray:
    """Real coefficients ``[1, a_1, ..., a_n]`` of ``prod(s - p_i)``; checks ``poles``."""
    try:
        p = np.asarray(poles, dtype=np.complex128).ravel()
    except (TypeError, ValueError) as exc:
        raise TypeError(f"poles must be numbers, got {type(poles).__name__}") from exc
    if p.size != n:
        raise ValueError(f"poles must hold {n} values (one per state), got {p.size}")
    if not np.all(np.isfinite(p)):
        raise ValueError(f"poles must be finite, got {p.tolist()}")
    coeffs = np.poly(p)
    scale = max(1.0, float(np.max(np.abs(coeffs))))
    if np.any(np.abs(coeffs.imag) > 1e-9 * scale):
        raise ValueError(f"poles must be real or come in complex-conjugate pairs, got {p.tolist()}")
    return coeffs.real


def ackermann_observer_gain(A: object, C: object, poles: object) -> FloatArray:
    """Observer gain by Ackermann's formula: ``eig(A - L C) = poles`` (single output).

    ``L = phi(A) O^-1 e_n`` with ``phi`` the desired characteristic polynomial,
    ``O = [C; C A; ...; C A^(n-1)]`` the observability matrix and ``e_n`` the last unit vector.
    Repeated poles are fine.

    Parameters
    ----------
    A : array_like (n, n)
        State matrix (continuous ``A`` or discrete ``F``).
    C : array_like (1, n) or (n,)
        Output row.
    poles : array_like (n,)
        Desired eigenvalues of ``A - L C``; complex ones in conjugate pairs.

    Returns
    -------
    ndarray (n,)
        The gain ``L``.

    Raises
    ------
    ValueError
        Bad shapes, poles not closed under conjugation, or ``(A, C)`` not observable.
    """
    a = as_float_array(A, "A", (None, None))
    n = a.shape[0]
    if a.shape != (n, n) or n == 0:
        raise ValueError(f"A must be square, got {a.shape}")
    c = as_float_array(C, "C", (None,) if np.ndim(C) == 1 else (1, n)).reshape(-1)
    if c.shape != (n,):
        raise ValueError(f"C must have shape (1, {n}), got {np.shape(C)}")
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(c))):
        raise ValueError("A and C must be finite")
    coeffs = _char_poly(poles, n)
    rows = [c]
    for _ in range(n - 1):
        rows.append(rows[-1] @ a)
    obs = np.array(rows)  # observability matrix O
    if np.linalg.matrix_rank(obs) < n:
        raise ValueError("(A, C) is not observable: the poles cannot be placed")
    phi = np.zeros((n, n))
    for coef in coeffs:  # Horner: phi(A) = A^n + a_1 A^(n-1) + ... + a_n I
        phi = phi @ a + coef * np.eye(n)
    e_n = np.zeros(n)
    e_n[-1] = 1.0
    return phi @ np.linalg.solve(obs, e_n)


def luenberger_gains(poles: object, *, discrete_dt: float | None = None,
                     form: str = "predictor") -> FloatArray:
    """Gains ``L = [L_1, L_2]`` of the double-integrator observer of report eq. 3.14.

    Parameters
    ----------
    poles : array_like (2,)
        Desired observer poles: in the s-plane (1/s) for continuous time, in the z-plane for
        discrete time. Repeated and complex-conjugate poles are allowed.
    discrete_dt : float, optional
        If given, design for the discretised model ``F = [[1, dt], [0, 1]]`` with this step (s).
    form : {"predictor", "current"}
        Discrete observer form (see the module docstring): poles of ``F - L C`` or of
        ``F - L C F``. Ignored in continuous time.

    Returns
    -------
    ndarray (2,)
        ``[L_1, L_2]`` (continuous: 1/s, 1/s^2; discrete: dimensionless, 1/s). The report's
        two-axis gain matrix ``[[L11, L12], [L21, L22]]`` is ``np.column_stack([L, L])`` when both
        axes share the poles. Continuous: ``L_1 = -(p_1 + p_2)``, ``L_2 = p_1 p_2``.
    """
    if discrete_dt is None:
        return ackermann_observer_gain(_A, _C, poles)  # eig(A - L C) = poles, eq. (3.14)
    dt = check_dt(discrete_dt, "discrete_dt")
    f = np.array([[1.0, dt], [0.0, 1.0]])  # expm(A dt), A^2 = 0
    if form == "predictor":
        return ackermann_observer_gain(f, _C, poles)
    if form == "current":
        return ackermann_observer_gain(f, _C @ f, poles)
    raise ValueError(f"form must be 'predictor' or 'current', got {form!r}")


class LuenbergerObserver:
    """Streaming two-axis (x, y) position/velocity observer, report eq. 3.14.

    Each axis is the double integrator observed in the discrete "current" form with the poles
    ``exp(p_i dt)`` of the requested continuous poles ``p_i``, recomputed for each step length,
    so the behaviour does not depend on the sample rate and irregular steps are handled.
    Between measurements (``z=None``) the state is only predicted (constant velocity).

    Parameters
    ----------
    poles : array_like (2,)
        Continuous-time observer poles, 1/s, real parts < 0 (e.g. ``(-3, -3)``), shared by x and y.
    dt : float
        Nominal step (s) used when :meth:`update` gets no ``dt``.
    initial_position : array_like (2,), optional
        Initial position, m; by default the first measurement (velocity 0).
    initial_velocity : array_like (2,)
        Initial velocity, m/s.

    Attributes
    ----------
    position, velocity : ndarray (2,)
        Current estimate (m, m/s), axes x, y.
    time : float
        Time since the start, s (sum of the steps).
    skipped : int
        Measurements ignored because they were not finite (treated as missing).
    """

    def __init__(self, poles: object, dt: float, *, initial_position: object = None,
                 initial_velocity: object = (0.0, 0.0)) -> None:
        _char_poly(poles, 2)
        p = np.asarray(poles, dtype=np.complex128).ravel()
        if np.any(p.real >= 0.0):
            raise ValueError(f"poles must have negative real parts (stable), got {p.tolist()}")
        self.poles = p
        self.dt = check_dt(dt)
        self.velocity = self._vec2(initial_velocity, "initial_velocity", allow_nan=False)
        self.initialised = initial_position is not None
        self.position = (np.zeros(2) if initial_position is None
                         else self._vec2(initial_position, "initial_position", allow_nan=False))
        self.time = 0.0
        self.skipped = 0
        self._gain_cache: tuple[float, float, float] = (math.nan, 0.0, 0.0)

    @staticmethod
    def _vec2(value: object, name: str, *, allow_nan: bool) -> FloatArray:
        v = as_float_array(value, name, (2,)).copy()
        if not allow_nan and not np.all(np.isfinite(v)):
            raise ValueError(f"{name} must be finite, got {v.tolist()}")
        return v

    def gains(self, dt: float) -> tuple[float, float]:
        """Current-form gains ``(L_1, L_2)`` for a step of ``dt`` seconds (poles ``exp(p dt)``).

        :func:`luenberger_gains` with ``form="current"`` on the z-plane poles ``exp(p_i dt)``
        of :attr:`poles`; the last step length's gains are kept for the next call.

        Parameters
        ----------
        dt : float
            Step length, s (> 0).

        Returns
        -------
        L_1, L_2 : float
            Gains on the position innovation (m): ``L_1`` dimensionless into the position,
            ``L_2`` 1/s into the velocity.

        Raises
        ------
        TypeError
            ``dt`` is not a real number.
        ValueError
            ``dt`` not finite or not > 0.
        """
        dt = check_dt(dt)
        if self._gain_cache[0] != dt:
            # report eq. (3.14), current form: F - L C F has determinant 1 - L_1 and trace
            # 2 - L_1 - L_2 dt, so poles z_i = exp(p_i dt) need L_1 = 1 - z_1 z_2 and
            # L_2 = (1 - z_1)(1 - z_2) / dt; in expm1 these hold for any step (Ackermann's
            # formula, luenberger_gains, lost the pole placement below dt ~ 1e-150 and above 1e150)
            m1, m2 = np.expm1(self.poles * dt).tolist()
            per_second = complex(m1.real / dt, m1.imag / dt)  # (z_1 - 1) / dt, without underflow
            self._gain_cache = (dt, -math.expm1((self.poles.sum() * dt).real), (per_second * m2).real)
        return self._gain_cache[1], self._gain_cache[2]

    def update(self, z: object, dt: float | None = None) -> tuple[FloatArray, FloatArray]:
        """Advance by ``dt`` and correct with the measured position ``z``.

        Parameters
        ----------
        z : array_like (2,) or None
            Measured position ``(x, y)``, m; ``None`` for a missing measurement (predict only).
            A non-finite measurement is treated as missing and counted in ``skipped``.
        dt : float, optional
            Time since the previous call, s, > 0 (a sample out of order would need ``dt <= 0``
            and is refused); default the nominal ``dt``.

        Returns
        -------
        position, velocity : ndarray (2,)
            Copies of the estimate after this step (m, m/s).
        """
        step = self.dt if dt is None else check_dt(dt)
        meas = None if z is None else self._vec2(z, "z", allow_nan=True)
        if meas is not None and not np.all(np.isfinite(meas)):
            self.skipped += 1
            meas = None
        self.time += step
        if not self.initialised:
            if meas is not None:
                self.position = meas
                self.initialised = True
            return self.position.copy(), self.velocity.copy()
        self.position = self.position + step * self.velocity  # x^- = F x, F = [[1, dt], [0, 1]]
        if meas is not None:
            l1, l2 = self.gains(step)
            innovation = meas - self.position  # z - C x^-
            self.position = self.position + l1 * innovation  # x = x^- + L (z - C x^-)
            self.velocity = self.velocity + l2 * innovation
        return self.position.copy(), self.velocity.copy()
