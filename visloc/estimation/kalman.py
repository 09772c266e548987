"""Position/velocity Kalman filter on filterpy's ``KalmanFilter``, with gating and RTS smoothing.

Fuses world-frame position fixes (marker maps, with their covariance), world-frame velocities
(optical flow rotated into the world frame) and, for the constant-velocity model, a world-frame
acceleration input (accelerometer with gravity removed) on irregular time steps.

Model and state ordering
------------------------
Each axis is an independent kinematic chain of ``order`` states: ``order = 2`` for the
constant-velocity model (``"cv"``: position, velocity) and ``order = 3`` for the
constant-acceleration model (``"ca"``: position, velocity, acceleration). The state keeps the
derivatives of one axis together, which is filterpy's ``order_by_dim=True`` block layout of
:func:`filterpy.common.Q_discrete_white_noise`::

    cv, dims=2:  x = [px, vx, py, vy]
    ca, dims=3:  x = [px, vx, ax, py, vy, ay, pz, vz, az]

so ``F = kron(I_dims, F_axis)`` and ``Q = Q_discrete_white_noise(order, dt, var, block_size=dims)``
are block diagonal with one block per axis. With ``dt`` the time since the previous step::

    F_axis(cv) = [[1, dt],        F_axis(ca) = [[1, dt, dt^2/2],
                  [0,  1]]                      [0,  1, dt    ],
                                                [0,  0, 1     ]]

Process noise: filterpy's discrete white-noise models (Bar-Shalom p. 274),
``Q_axis = G G^T var`` with ``G = [dt^2/2, dt]`` (``"cv"``: the acceleration is constant over a
step and white between steps) or ``G = [dt^2/2, dt, 1]`` (``"ca"``: the acceleration changes by a
white increment each step). ``accel_noise`` sets ``var`` in one of two ways
(``accel_noise_kind``):

- ``"std"`` (default): ``var = accel_noise^2`` per step, m/s^2 (filterpy's ``var`` as is): the
  standard deviation of the piecewise-constant acceleration (``"cv"``) or of its change per step
  (``"ca"``). This noise is defined per step, so the tuning depends on the sample rate: call
  :meth:`PositionVelocityKF.predict` at every sample time, also when the measurement is missing.
- ``"density"``: the spectral density of the white noise driving the highest
  derivative, m/s^2/sqrt(Hz) for ``"cv"`` (white acceleration) and m/s^3/sqrt(Hz) for ``"ca"``
  (white jerk). ``var`` is scaled with ``dt`` so that the highest derivative diffuses by
  ``accel_noise^2 dt`` per step (``var = accel_noise^2 / dt`` for ``"cv"``,
  ``accel_noise^2 dt`` for ``"ca"``): the tuning does not depend on the sample rate, and one long
  predict over a gap grows ``P`` almost as much as many short ones. At a fixed rate ``1/dt``,
  density ``q`` is the same as ``"std"`` with ``q / sqrt(dt)`` (``"cv"``) or ``q sqrt(dt)``
  (``"ca"``).

Accelerometer input (``"cv"`` only): ``x = F x + B u`` with ``B_axis = [dt^2/2, dt]`` and ``u`` the
world-frame acceleration in the state's axes (rotate the specific force into the world frame and
remove gravity first). With an input, the step's ``Q`` uses ``var = accel_std^2`` instead, the
per-sample variance of the accelerometer's error (a piecewise-constant white acceleration error),
in place of the unknown manoeuvre.

Measurements are gated: an innovation ``y = z - H x`` with ``S = H P H^T + R`` is rejected when its
squared Mahalanobis distance ``y^T S^-1 y`` exceeds the ``gate`` quantile of the chi-square
distribution with ``dim(z)`` degrees of freedom. Non-finite measurements are skipped. Both are
counted, and neither changes the state. A measurement refused with an error (bad shape, ``R`` or
``std``) changes nothing, not even the clock: its ``t=`` is predicted to only after the checks.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from filterpy.kalman import KalmanFilter
from scipy.stats import chi2

from visloc._checks import all_finite
from visloc.estimation._checks import FloatArray, as_float_array, check_real

__all__ = ["PositionVelocityKF"]

#: Standard deviation (m) standing for "position unknown" before the first fix and after a reset.
UNKNOWN_POSITION_STD = 1.0e3
_KINDS = ("position", "velocity", "acceleration")


def _axis_F(order: int, dt: float) -> FloatArray:
    if order == 2:
        return np.array([[1.0, dt], [0.0, 1.0]])
    return np.array([[1.0, dt, 0.5 * dt * dt], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])


def _axis_Q(order: int, dt: float) -> FloatArray:
    """One axis block of filterpy's ``Q_discrete_white_noise(order, dt, var=1)``, the same
    expressions (so the same floating-point values)."""
    if order == 2:
        return np.array([[.25 * dt**4, .5 * dt**3],
                         [.5 * dt**3, dt**2]])
    return np.array([[.25 * dt**4, .5 * dt**3, .5 * dt**2],
                     [.5 * dt**3, dt**2, dt],
                     [.5 * dt**2, dt, 1.0]])


def _block_diag(block: FloatArray, n: int) -> FloatArray:
    """``n`` copies of the square ``block`` on the diagonal, zeros elsewhere: what
    ``scipy.linalg.block_diag(*[block] * n)`` gives, faster (and, for the finite non-negative
    blocks of ``F`` and ``Q`` here, also what ``np.kron(np.eye(n), block)`` gives)."""
    k = block.shape[0]
    out = np.zeros((n * k, n * k))
    for i in range(n):
        out[i * k:(i + 1) * k, i * k:(i + 1) * k] = block
    return out


class PositionVelocityKF:
    """Kalman filter for position, velocity (and acceleration) on irregular time steps.

    Parameters
    ----------
    dims : {2, 3}
        Number of axes (``(x, y)`` or ``(x, y, z)``) of the world frame.
    model : {"cv", "ca"}
        Constant velocity (state ``[p, v]`` per axis, ``dim_x = 2 dims``) or constant acceleration
        (``[p, v, a]`` per axis, ``dim_x = 3 dims``); ordering in the module docstring.
    accel_noise : float
        Process noise, > 0, in the units of ``accel_noise_kind`` (module docstring): by default
        the standard deviation (m/s^2) of the acceleration held constant over each step
        (``"cv"``) or of the acceleration's change per step (``"ca"``).
    accel_noise_kind : {"std", "density"}
        ``"std"``: ``accel_noise`` is filterpy's per-step standard deviation (m/s^2),
        ``var = accel_noise^2``; ``"density"``: it is the spectral density of the white
        acceleration (``"cv"``, m/s^2/sqrt(Hz)) or jerk (``"ca"``, m/s^3/sqrt(Hz)), independent
        of the sample rate.
    initial_position : array_like (dims,), optional
        Initial position, m. By default unknown (zero with ``UNKNOWN_POSITION_STD``), so the first
        position measurement sets it.
    initial_velocity : array_like (dims,), optional
        Initial velocity, m/s (default zero).
    initial_std : float or sequence of float
        Initial standard deviation of each derivative, one value for all or one per derivative:
        ``(position m, velocity m/s[, acceleration m/s^2])``. The position value is ignored when
        ``initial_position`` is None. The initial acceleration of ``"ca"`` is zero.
    gate : float or None
        Probability of the chi-square gate (default 0.999: 0.1 % of good measurements are
        rejected); None accepts every finite measurement.
    reset_after : int or None
        After this many consecutive rejected position measurements, the next one that fails the
        gate re-initialises the filter on it (the position becomes unknown, the velocity keeps
        its mean with the initial covariance) and ``resets`` counts it: a persistent jump is
        taken as real. None never resets.
    keep_history : bool
        Store ``(t, x, P)`` per time step and what :meth:`rts_smooth` needs.

    Attributes
    ----------
    kf : filterpy.kalman.KalmanFilter
        The wrapped filter (``x`` as a ``(dim_x, 1)`` column).
    rejected : dict of str -> int
        Measurements rejected by the gate, per kind (``"position"``, ``"velocity"``,
        ``"acceleration"``).
    skipped : dict of str -> int
        Non-finite measurements (or covariances) ignored, per kind, and ``"accel_input"`` for
        non-finite accelerometer inputs (that step is then predicted without input).
    resets : int
        Re-initialisations after ``reset_after`` consecutive position rejections.
    last_nis : float
        Squared Mahalanobis distance (normalised innovation squared) of the last finite
        measurement, accepted or not; NaN before any.
    """

    def __init__(self, dims: int = 2, *, model: str = "cv", accel_noise: float = 1.0,
                 accel_noise_kind: str = "std", initial_position: object = None,
                 initial_velocity: object = None,
                 initial_std: float | Sequence[float] = 1.0, gate: float | None = 0.999,
                 reset_after: int | None = 10, keep_history: bool = True) -> None:
        if not isinstance(dims, int) or isinstance(dims, bool):
            raise TypeError(f"dims must be an int, got {type(dims).__name__}")
        if dims not in (2, 3):
            raise ValueError(f"dims must be 2 or 3, got {dims}")
        if model not in ("cv", "ca"):
            raise ValueError(f"model must be 'cv' or 'ca', got {model!r}")
        self.dims = dims
        self.model = model
        self.order = 2 if model == "cv" else 3
        self.dim_x = self.order * dims
        self.accel_noise = check_real(accel_noise, "accel_noise", positive=True)
        if accel_noise_kind not in ("density", "std"):
            raise ValueError(f"accel_noise_kind must be 'std' or 'density', got "
                             f"{accel_noise_kind!r}")
        self.accel_noise_kind = accel_noise_kind
        if gate is not None:
            gate = check_real(gate, "gate")
            if not 0.0 < gate < 1.0:
                raise ValueError(f"gate must be a probability in (0, 1) or None, got {gate}")
        self._gate = gate
        # every measurement has dims components: one chi-square threshold for all
        self._gate_d2 = math.inf if gate is None else float(chi2.ppf(gate, dims))
        if reset_after is not None:
            if not isinstance(reset_after, int) or isinstance(reset_after, bool):
                raise TypeError(f"reset_after must be an int or None, got "
                                f"{type(reset_after).__name__}")
            if reset_after < 1:
                raise ValueError(f"reset_after must be >= 1, got {reset_after}")
        self.reset_after = reset_after
        self.keep_history = bool(keep_history)
        self._initial_var = self._initial_variances(initial_std)

        idx = np.arange(dims) * self.order
        self._idx = {"position": idx, "velocity": idx + 1, "acceleration": idx + 2}
        self._blocks = {kind: np.ix_(i, i) for kind, i in self._idx.items()}  # made once: np.ix_ per call cost
        # more than the copy (visloc.io.mavlink sends both blocks with every fix)
        self._H = {kind: np.eye(self.dim_x)[i] for kind, i in self._idx.items()
                   if kind != "acceleration" or model == "ca"}

        self.kf = KalmanFilter(dim_x=self.dim_x, dim_z=dims)
        x = np.zeros(self.dim_x)
        if initial_position is not None:
            x[idx] = self._finite_vec(initial_position, "initial_position")
        if initial_velocity is not None:
            x[idx + 1] = self._finite_vec(initial_velocity, "initial_velocity")
        self.kf.x = x.reshape(-1, 1)
        self.kf.P = self._initial_covariance(position_known=initial_position is not None)

        self.t: float | None = None
        self.rejected = dict.fromkeys(_KINDS, 0)
        self.skipped = dict.fromkeys((*_KINDS, "accel_input"), 0)
        self.resets = 0
        self.last_nis = math.nan
        self._consecutive_rejections = 0
        self._step_cache: dict[tuple[float, float], tuple[FloatArray, FloatArray, FloatArray | None]] = {}
        # per time step: t, posterior x and P, and (for RTS) the step's F, prior x and prior P
        self._ts: list[float] = []
        self._xs: list[FloatArray] = []
        self._Ps: list[FloatArray] = []
        self._steps: list[tuple[FloatArray, FloatArray, FloatArray] | None] = []

    # ----------------------------------------------------------------------------- helpers
    def _initial_variances(self, initial_std: object) -> FloatArray:
        if np.ndim(initial_std) == 0:
            std = np.full(self.order, check_real(initial_std, "initial_std", positive=True))
        else:
            std = as_float_array(initial_std, "initial_std", (self.order,))
            if not np.all(np.isfinite(std) & (std > 0.0)):
                raise ValueError(f"initial_std must be finite and > 0, got {std.tolist()}")
        return std**2

    def _initial_covariance(self, *, position_known: bool) -> FloatArray:
        var = self._initial_var.copy()
        if not position_known:
            var[0] = UNKNOWN_POSITION_STD**2
        return np.diag(np.tile(var, self.dims))

    def _finite_vec(self, value: object, name: str) -> FloatArray:
        v = as_float_array(value, name, (self.dims,))
        if not np.all(np.isfinite(v)):
            raise ValueError(f"{name} must be finite, got {v.tolist()}")
        return v.copy()

    def _record(self, t: float, step: tuple[FloatArray, FloatArray, FloatArray] | None) -> None:
        if self.keep_history:
            self._ts.append(t)
            self._xs.append(self.x)
            self._Ps.append(self.P)
            self._steps.append(step)

    def _rewrite_last(self) -> None:
        if self.keep_history:
            self._xs[-1] = self.x
            self._Ps[-1] = self.P

    # ------------------------------------------------------------------------------- state
    @property
    def gate(self) -> float | None:
        """Probability of the chi-square gate (None: no gating)."""
        return self._gate

    @property
    def gate_threshold(self) -> float:
        """Squared Mahalanobis distance above which a measurement is rejected (inf: no gate)."""
        return self._gate_d2

    @property
    def x(self) -> FloatArray:
        """State (dim_x,), ordered per axis ``[p, v(, a)]`` (m, m/s, m/s^2); a copy."""
        return self.kf.x[:, 0].copy()

    @property
    def P(self) -> FloatArray:
        """State covariance (dim_x, dim_x), same ordering as ``x``; a copy."""
        return self.kf.P.copy()

    @property
    def position(self) -> FloatArray:
        """Position estimate (dims,), m."""
        return self.kf.x[self._idx["position"], 0].copy()

    @property
    def velocity(self) -> FloatArray:
        """Velocity estimate (dims,), m/s."""
        return self.kf.x[self._idx["velocity"], 0].copy()

    @property
    def position_covariance(self) -> FloatArray:
        """Covariance of the position (dims, dims), m^2; a copy."""
        return self.kf.P[self._blocks["position"]]  # (advanced indexing: already a copy)

    @property
    def velocity_covariance(self) -> FloatArray:
        """Covariance of the velocity (dims, dims), m^2/s^2; a copy."""
        return self.kf.P[self._blocks["velocity"]]

    @property
    def acceleration(self) -> FloatArray:
        """Acceleration estimate (dims,), m/s^2 (``"ca"`` only)."""
        if self.model != "ca":
            raise AttributeError("acceleration is only estimated with model='ca'")
        return self.kf.x[self._idx["acceleration"], 0].copy()

    @property
    def history(self) -> list[tuple[float, FloatArray, FloatArray]]:
        """``(t, x, P)`` after the updates at each time step, oldest first (empty when
        ``keep_history`` is False); ``x`` (dim_x,), ``P`` (dim_x, dim_x)."""
        return [(t, x.copy(), p.copy()) for t, x, p in zip(self._ts, self._xs, self._Ps)]

    # ----------------------------------------------------------------------------- predict
    def transition(self, dt: float, *,
                   accel_std: float | None = None) -> tuple[FloatArray, FloatArray]:
        """``F`` and ``Q`` (dim_x, dim_x) of a step of ``dt`` seconds (>= 0).

        ``Q = Q_discrete_white_noise(order, dt, var, block_size=dims)`` in filterpy's
        ``order_by_dim`` layout, which is the layout of ``x``. ``var`` follows ``accel_noise`` and
        ``accel_noise_kind``, or is ``accel_std^2`` when ``accel_std`` (m/s^2, per step) is given.
        The arrays are read-only (kept for the next step of the same length).

        Parameters
        ----------
        dt : float
            Step length, s (>= 0). ``dt = 0`` gives ``F = I`` and ``Q = 0``, except with
            ``model="ca"`` and a per-step ``var`` (``accel_noise_kind="std"`` or ``accel_std``):
            filterpy's formula then leaves ``var`` on each acceleration's diagonal
            (``G = [0, 0, 1]``). :meth:`predict` never takes a zero-length step.
        accel_std : float, optional
            Standard deviation of the acceleration input's error per step, m/s^2 (> 0):
            ``var = accel_std^2`` whatever ``accel_noise_kind``. None: ``var`` from
            ``accel_noise``.

        Returns
        -------
        F : ndarray (dim_x, dim_x)
            State transition, ``kron(I_dims, F_axis)`` (module docstring), read-only.
        Q : ndarray (dim_x, dim_x)
            Process noise covariance (units of ``x`` times ``x``: m^2, m^2/s, m^2/s^2, ...),
            read-only.

        Raises
        ------
        TypeError
            ``dt`` or ``accel_std`` is not a real number.
        ValueError
            ``dt`` not finite or < 0, or ``accel_std`` not finite or <= 0.
        """
        F, Q, _ = self._step(dt, accel_std)
        return F, Q

    def _step(self, dt: float, accel_std: float | None) -> tuple[FloatArray, FloatArray, FloatArray | None]:
        """:meth:`transition`'s ``F``, ``Q`` and the input matrix ``B`` (``"cv"``), cached by step."""
        dt = check_real(dt, "dt", nonneg=True)
        if accel_std is not None:
            var = check_real(accel_std, "accel_std", positive=True) ** 2
        elif self.accel_noise_kind == "std":
            var = self.accel_noise**2
        elif self.order == 2:
            var = self.accel_noise**2 / dt if dt > 0.0 else 0.0  # velocity: + q dt per step
        else:
            var = self.accel_noise**2 * dt  # acceleration: + q dt per step
        key = (dt, var)
        cached = self._step_cache.get(key)
        if cached is None:  # a stream at a fixed rate asks for the same step again and again
            # F = kron(I, F_axis); Q = Q_discrete_white_noise(order, dt, var, block_size=dims),
            # built directly (the same values: this runs at every step of a jittered stream)
            try:
                with np.errstate(all="ignore"):  # judged below
                    F = _block_diag(_axis_F(self.order, dt), self.dims)
                    Q = _block_diag(_axis_Q(self.order, dt), self.dims) * var
            except OverflowError:  # dt ** 4 beyond float's range
                raise ValueError(f"dt: a step of {dt:g} s is beyond what the filter's model can hold") from None
            if not (np.isfinite(F).all() and np.isfinite(Q).all()):
                raise ValueError(f"dt: a step of {dt:g} s gives a non-finite transition or process noise")
            B = None
            if self.order == 2:
                B = np.zeros((self.dim_x, self.dims))
                B[0::2, :] = np.diag(np.full(self.dims, 0.5 * dt * dt))
                B[1::2, :] = np.diag(np.full(self.dims, dt))
            for a in (F, Q, B):
                if a is not None:
                    a.setflags(write=False)
            if len(self._step_cache) >= 16:
                self._step_cache.clear()
            cached = self._step_cache[key] = (F, Q, B)
        return cached

    def predict(self, t: float, accel: object = None, *, accel_std: float | None = None) -> None:
        """Advance the estimate to time ``t``.

        The first call only sets the clock. A call at the current time does nothing.

        Parameters
        ----------
        t : float
            Time, s; not earlier than the previous time.
        accel : array_like (dims,), optional
            World-frame acceleration over the step, m/s^2, in the state's axes (``"cv"`` only),
            used as the control input ``B u``. Non-finite values drop the input for this step
            (counted in ``skipped["accel_input"]``).
        accel_std : float, optional
            Standard deviation (m/s^2) of ``accel``'s error per sample; when the input is used,
            ``Q`` of this step is built from it instead of ``accel_noise`` (default: from
            ``accel_noise`` as without input).

        Raises
        ------
        ValueError
            ``t`` not finite or earlier than the last time ("out-of-order timestamp"), bad
            ``accel`` shape, ``accel`` with ``model="ca"``; a step from the last time so long or
            so short that the model's ``F`` or ``Q`` is not finite (nothing changes then).
        """
        t = check_real(t, "t")
        u = None
        if accel is not None:
            if self.model != "cv":
                raise ValueError("accel input needs model='cv'; with model='ca' use "
                                 "update_acceleration")
            u = as_float_array(accel, "accel", (self.dims,))
        std = None if accel_std is None else check_real(accel_std, "accel_std", positive=True)
        if self.t is not None and t < self.t:
            raise ValueError(f"out-of-order timestamp: t={t!r} is earlier than the last time "
                             f"{self.t!r}")
        if u is not None and not all_finite(u):  # counted once the call is known to stand
            self.skipped["accel_input"] += 1
            u = None
        if self.t is None:
            self.t = t
            self._record(t, None)
            return
        dt = t - self.t
        if dt == 0.0:
            return
        F, Q, B = self._step(dt, std if u is not None else None)
        if u is None:
            self.kf.predict(F=F, Q=Q)  # x = F x; P = F P F^T + Q
        else:
            self.kf.predict(u=u.reshape(-1, 1), B=B, F=F, Q=Q)  # x = F x + B u
        self.kf.P = 0.5 * (self.kf.P + self.kf.P.T)
        self.t = t
        if self.keep_history:  # (x and P are copies: none made for nothing)
            self._record(t, (F, self.x, self.P))

    # ------------------------------------------------------------------------------ update
    def _measurement_cov(self, R: object, std: object, name: str) -> FloatArray | None:
        """(dims, dims) covariance from ``R`` or ``std``; None when it is not finite."""
        if (R is None) == (std is None):
            raise ValueError(f"give exactly one of R and std for the {name} measurement")
        if std is not None:
            shape = () if np.ndim(std) == 0 else (self.dims,)
            s = np.broadcast_to(as_float_array(std, "std", shape), (self.dims,))
            if not np.all(np.isfinite(s)):
                return None
            if np.any(s <= 0.0):
                raise ValueError(f"std must be > 0, got {s.tolist()}")
            return np.diag(s**2)
        cov = as_float_array(R, "R", (self.dims, self.dims))
        if not all_finite(cov):
            return None
        # np.allclose(cov, cov.T, rtol=1e-9, atol=1e-12 max|cov|) on floats (finite here): the
        # same test as on the arrays, several times faster on a few values
        d, v = self.dims, cov.ravel().tolist()
        atol = 1e-12 * max(map(abs, v))
        if any(abs(v[i * d + j] - v[j * d + i]) > atol + 1e-9 * abs(v[j * d + i]) for i in range(d) for j in range(d)):
            raise ValueError(f"R must be symmetric, got {cov.tolist()}")
        try:
            np.linalg.cholesky(cov)
        except np.linalg.LinAlgError:
            raise ValueError(f"R must be positive definite, got {cov.tolist()}") from None
        return 0.5 * (cov + cov.T)

    def _update(self, kind: str, z: object, R: object, std: object, t: float | None) -> bool:
        if t is None and self.t is None:
            raise ValueError(f"no time yet for the {kind} measurement: pass t= or call "
                             f"predict(t) first")
        zz = as_float_array(z, "z", (self.dims,))  # checked before predict moves the clock
        cov = self._measurement_cov(R, std, kind)
        if t is not None:
            self.predict(t)
        if cov is None or not all_finite(zz):
            self.skipped[kind] += 1
            return False
        H = self._H[kind]
        y = zz - H @ self.kf.x[:, 0]  # innovation y = z - H x
        S = H @ self.kf.P @ H.T + cov  # S = H P H^T + R
        self.last_nis = float(y @ np.linalg.solve(S, y))
        if self.last_nis > self._gate_d2:
            if kind != "position":
                self.rejected[kind] += 1
                return False
            if self.reset_after is None or self._consecutive_rejections < self.reset_after:
                self.rejected[kind] += 1
                self._consecutive_rejections += 1
                return False
            self._reset()
        self.kf.update(zz.reshape(-1, 1), R=cov, H=H)  # x += K y; P Joseph form
        self.kf.P = 0.5 * (self.kf.P + self.kf.P.T)
        if kind == "position":
            self._consecutive_rejections = 0
        self._rewrite_last()
        return True

    def _reset(self) -> None:
        self.resets += 1
        self._consecutive_rejections = 0
        self.kf.P = self._initial_covariance(position_known=False)
        if self.keep_history and self._steps[-1] is not None:
            F, x_prior, _ = self._steps[-1]
            self._steps[-1] = (F, x_prior, self.P)  # the reset enters the smoother as noise

    def update_position(self, z: object, R: object = None, *, std: object = None,
                        t: float | None = None) -> bool:
        """Correct with a world-frame position fix.

        Parameters
        ----------
        z : array_like (dims,)
            Measured position, m.
        R : array_like (dims, dims), optional
            Its covariance, m^2, symmetric positive definite: e.g. the camera-centre block of a
            marker-map pose propagated from ``MapPose.pose.covariance`` (which is the covariance
            of ``T_cam_map``'s parameters, not of the centre).
        std : float or array_like (dims,), optional
            Standard deviation per axis, m, instead of ``R``.
        t : float, optional
            Time of the measurement, s; if given, :meth:`predict` runs after the argument checks.

        Returns
        -------
        bool
            Whether the measurement was used (False when skipped as non-finite or rejected by the
            gate).
        """
        return self._update("position", z, R, std, t)

    def update_velocity(self, v: object, R: object = None, *, std: object = None,
                        t: float | None = None) -> bool:
        """Correct with a world-frame velocity (e.g. optical flow rotated into the world frame).

        Parameters
        ----------
        v : array_like (dims,)
            Measured velocity, m/s.
        R : array_like (dims, dims), optional
            Its covariance, (m/s)^2.
        std : float or array_like (dims,), optional
            Standard deviation per axis, m/s, instead of ``R``.
        t : float, optional
            Time of the measurement, s; if given, :meth:`predict` runs after the argument checks.

        Returns
        -------
        bool
            Whether the measurement was used.
        """
        return self._update("velocity", v, R, std, t)

    def update_acceleration(self, a: object, R: object = None, *, std: object = None,
                            t: float | None = None) -> bool:
        """Correct the ``"ca"`` model's acceleration with a world-frame measurement, m/s^2.

        Same arguments as :meth:`update_velocity` (units m/s^2); ValueError with ``"cv"``
        (feed the accelerometer to :meth:`predict` there).

        Parameters
        ----------
        a : array_like (dims,)
            Measured acceleration, m/s^2, world frame, in the state's axes (gravity removed).
        R : array_like (dims, dims), optional
            Its covariance, (m/s^2)^2, symmetric positive definite.
        std : float or array_like (dims,), optional
            Standard deviation per axis, m/s^2, instead of ``R``.
        t : float, optional
            Time of the measurement, s; if given, :meth:`predict` runs after the argument checks.

        Returns
        -------
        bool
            Whether the measurement was used (False when skipped as non-finite, counted in
            ``skipped["acceleration"]``, or rejected by the gate, counted in
            ``rejected["acceleration"]``).

        Raises
        ------
        ValueError
            ``model="cv"``; no time yet (no ``t`` and :meth:`predict` never called); ``a`` not
            (dims,); both or neither of ``R`` and ``std``; ``std`` <= 0; ``R`` not (dims, dims),
            not symmetric or not positive definite; or ``t`` as in :meth:`predict`.
        TypeError
            ``a``, ``R`` or ``std`` is not numeric, or ``t`` not a real number.
        """
        if self.model != "ca":
            raise ValueError("update_acceleration needs model='ca'; with model='cv' pass "
                             "accel= to predict")
        return self._update("acceleration", a, R, std, t)

    # --------------------------------------------------------------------------- smoothing
    def rts_smooth(self) -> tuple[FloatArray, FloatArray]:
        """Rauch-Tung-Striebel smoothing of the stored history (offline logs).

        Uses each step's own ``F``, prior mean (which includes any ``B u``) and prior covariance
        (which includes that step's ``Q``), so variable steps and accelerometer inputs are
        handled (filterpy's ``rts_smoother`` recomputes the prior as ``F x`` and would drop
        ``B u``; without inputs the two agree). The filter itself is not changed.

        Returns
        -------
        xs : ndarray (N, dim_x)
            Smoothed states at the ``N`` history times.
        Ps : ndarray (N, dim_x, dim_x)
            Their covariances.

        Raises
        ------
        ValueError
            No history (``keep_history`` False or nothing predicted yet).
        """
        if not self._ts:
            raise ValueError("no history to smooth: keep_history is False or predict(t) was "
                             "never called")
        xs = np.array(self._xs)
        Ps = np.array(self._Ps)
        for k in range(len(xs) - 2, -1, -1):
            F, x_prior, P_prior = self._steps[k + 1]  # type: ignore[misc]
            C = np.linalg.solve(P_prior, F @ Ps[k]).T  # C = P_k F^T P_prior^-1 (RTS gain)
            xs[k] = xs[k] + C @ (xs[k + 1] - x_prior)
            Ps[k] = Ps[k] + C @ (Ps[k + 1] - P_prior) @ C.T
            Ps[k] = 0.5 * (Ps[k] + Ps[k].T)
        return xs, Ps
