"""Gauss-Newton refinement of a camera pose on the reprojection error.

The report (§3.2.2, Appendix G) searches the rotation and translation with a Gauss-Newton
iteration whose parameters are the states ``[x y z phi theta psi]``. Here: the same
parameters, an analytic Jacobian, Marquardt's damping for starts far from the minimum, and
several starts refined at once (vectorised over the starts).

Residuals are in pixels of the undistorted image: ``f * (projected - observed)`` with the
observed points in normalized image coordinates and ``f = (fx, fy)``.

:func:`levenberg_marquardt` runs compiled (``visloc.pose._lm``, built with the package: the
same steps without numpy's per-call cost, which dominates for a few dozen points) when it was
built, and in numpy otherwise.
"""

from __future__ import annotations

import math
import numbers

import numpy as np
from numpy.typing import ArrayLike

from visloc._compiled import use_compiled
from visloc.pose.rotations import euler_to_matrix
from visloc.types import FloatArray

#: LM stops a start when a step lowers its squared error by less than this fraction (at a
#: noisy minimum the parameters are then within ~1e-3 standard deviations) ...
RTOL = 1e-6
#: ... or by less than this one when its error is over 1.5 times the lowest start's. Any
#: start but the lowest stops after :data:`MAX_ITER_OTHER` iterations (a flip's error is
#: wanted to a few digits; a start that has found no minimum nearby is wanted not at all).
RTOL_OTHER = 1e-4
MAX_ITER_OTHER = 6
#: ... and any start stops when the predicted decrease is below RTOL of its error plus this
#: (squared residual units): the floating-point floor of exact data.
ATOL = 1e-20

_EYE6 = np.eye(6)

try:
    from visloc.pose import _lm
except ImportError:  # installed without a C compiler: the numpy version below
    _lm = None

#: Whether :func:`levenberg_marquardt` runs compiled.
NATIVE_LM = _lm is not None

# Rows of q x a and q x b (a = (1, 0, -u), b = (0, 1, -v)) as q @ _CROSS, q = R X a row:
# (-qy, qx, 0) multiplies u (and v); (0, qz, -qy) and (-qz, 0, qx) are the constant parts.
_CROSS = np.array(
    [
        [0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0],
        [-1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, 0.0, 1.0, 0.0, -1.0, 0.0, 0.0],
    ]
)


def rotations_and_rates(params: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Rotation matrices of parameter vectors and the matrices that turn Euler rates into
    rotation vectors.

    Scalar code: S is a handful and numpy's per-call cost would dominate.

    Parameters
    ----------
    params : ndarray (S, 6)
        ``[tx, ty, tz, phi, theta, psi]`` (angles in rad; only they are read).

    Returns
    -------
    R : ndarray (S, 3, 3)
        ``R = Rz(psi) Ry(theta) Rx(phi)``: object frame into camera frame.
    W : ndarray (S, 3, 3)
        Columns ``R e_x``, ``Rz(psi) e_y`` and ``e_z``: the small rotation (camera frame, rad)
        of angle changes ``d = [dphi, dtheta, dpsi]`` (rad) is ``w = W d``.
    """
    R = []
    W = []
    for phi, theta, psi in params[:, 3:].tolist():
        cph, sph = math.cos(phi), math.sin(phi)
        cth, sth = math.cos(theta), math.sin(theta)
        cps, sps = math.cos(psi), math.sin(psi)
        r00, r10 = cps * cth, sps * cth
        R.append(
            (
                (r00, cps * sth * sph - sps * cph, cps * sth * cph + sps * sph),
                (r10, sps * sth * sph + cps * cph, sps * sth * cph - cps * sph),
                (-sth, cth * sph, cth * cph),
            )
        )
        W.append(((r00, -sps, 0.0), (r10, cps, 0.0), (-sth, 0.0, 1.0)))
    return np.array(R), np.array(W)


def _project(
    params: FloatArray, X: FloatArray, R: FloatArray | None = None
) -> tuple[FloatArray, FloatArray, FloatArray, bool]:
    """``q = R X`` (S, 3, N), normalized projections ``uv`` (S, 2, N), ``1/z`` (S, N) (``0``
    for points not in front of the camera) and whether there are any such points."""
    q = (rotations_and_rates(params)[0] if R is None else R) @ X
    z = q[:, 2] + params[:, 2:3]
    behind = bool((z <= 0.0).any())
    if behind:
        z = np.where(z > 0.0, z, np.inf)
    iz = 1.0 / z
    uv = (q[:, :2] + params[:, :2, None]) * iz[:, None]
    return q, uv, iz, behind


def reprojection_residuals(
    params: FloatArray, X: FloatArray, xy: FloatArray, f: FloatArray
) -> FloatArray:
    """Reprojection residuals of S parameter vectors.

    Parameters
    ----------
    params : ndarray (S, 6)
        ``[tx, ty, tz, phi, theta, psi]``: object frame into camera frame, translation in the
        unit of ``X``, ``R = Rz(psi) Ry(theta) Rx(phi)`` (rad).
    X : ndarray (3, N)
        Object points, columns, object frame.
    xy : ndarray (2, N)
        Observed normalized image coordinates (undistorted, ``K^-1``), columns.
    f : ndarray (2, 1)
        ``[[fx], [fy]]``, px: the residuals' weights (1 gives normalized units).

    Returns
    -------
    ndarray (S, 2N)
        ``[du_0..du_N-1, dv_0..dv_N-1]`` = ``f * (projected - observed)``, px; every entry of
        a start that puts any point behind the camera is ``inf``.
    """
    _, uv, iz, behind = _project(params, X)
    r = ((uv - xy) * f).reshape(len(params), -1)
    if behind:
        r[(iz == 0.0).any(axis=1)] = np.inf
    return r


def reprojection_rms(params: ArrayLike, X: ArrayLike, xy: ArrayLike, f: ArrayLike, *, group: int = 4,
                     native: bool | None = None) -> FloatArray:
    """The RMS reprojection error of each run of ``group`` points (a marker's four corners)
    under one or several parameter vectors.

    Parameters
    ----------
    params : array_like (6,) or (S, 6)
        As for :func:`reprojection_residuals`.
    X : array_like (3, N)
        Object points, columns, object frame; N a multiple of ``group``.
    xy : array_like (2, N)
        Observed normalized image coordinates, columns.
    f : array_like (2, 1)
        ``[[fx], [fy]]``, px.
    group : int
        Points per run (>= 1): runs are ``X[:, :group]``, ``X[:, group:2 * group]``, ...
    native : bool or None
        As for :func:`levenberg_marquardt`.

    Returns
    -------
    ndarray (N / group,) or (S, N / group)
        ``sqrt(mean(|f * (projected - observed)|^2))`` over each run, px; ``inf`` where a point
        of the run is not in front of the camera (depth <= 1e-9).

    Raises
    ------
    ValueError
        Shapes not as above, or ``group`` not a whole number >= 1 dividing N.
    RuntimeError
        ``native=True`` but the compiled version was not built.
    """
    p = np.asarray(params, np.float64)
    X = np.asarray(X, np.float64)
    xy = np.asarray(xy, np.float64)
    f = np.asarray(f, np.float64)
    if p.shape[-1:] != (6,) or p.ndim not in (1, 2):
        raise ValueError(f"params must have shape (6,) or (S, 6), got {p.shape}")
    if X.ndim != 2 or X.shape[0] != 3 or xy.shape != (2, X.shape[1]) or f.shape != (2, 1):
        raise ValueError(f"X must be (3, N), xy (2, N) and f (2, 1), got {X.shape}, {xy.shape} and {f.shape}")
    if isinstance(group, bool) or not isinstance(group, numbers.Integral) or group < 1 or X.shape[1] % group:
        raise ValueError(f"group must be a whole number >= 1 dividing N = {X.shape[1]}, got {group!r}")
    m = X.shape[1] // group
    if use_compiled(native, _lm, "visloc.pose._lm"):
        raw = _lm.group_rms(np.ascontiguousarray(p), np.ascontiguousarray(X), np.ascontiguousarray(xy),
                            float(f[0, 0]), float(f[1, 0]), int(group))
        return np.frombuffer(raw, np.float64).reshape(*p.shape[:-1], m).copy()
    R = euler_to_matrix(p[..., 3:])  # (..., 3, 3)
    q = X.T @ np.swapaxes(R, -1, -2) + p[..., None, :3]  # (..., N, 3)
    z = np.where(q[..., 2] > 1e-9, q[..., 2], np.nan)
    d = (q[..., :2] / z[..., None] - xy.T) * f[:, 0]
    rms = np.sqrt(np.vecdot(d, d).reshape(*p.shape[:-1], m, group).mean(axis=-1))
    return np.where(np.isfinite(rms), rms, np.inf)


def residuals_and_jacobian(
    params: FloatArray, X: FloatArray, xy: FloatArray, f: FloatArray
) -> FloatArray:
    """The analytic Jacobian and the residuals of S parameter vectors at once.

    Parameters
    ----------
    params, X, xy, f
        As for :func:`reprojection_residuals`.

    Returns
    -------
    ndarray (S, 2N, 7)
        ``E = [J | r]``: the Jacobian ``d r / d params`` (px per unit of ``X`` for the
        translation, px/rad for the angles) in its first six columns and the residuals of
        :func:`reprojection_residuals` (px) in the last, so that ``E^T E`` holds ``J^T J``,
        ``J^T r`` and ``r^T r`` at once. The last column is ``inf`` for a start that puts any
        point behind the camera.
    """
    S = params.shape[0]
    N = X.shape[1]
    R, W = rotations_and_rates(params)
    q, uv, iz, behind = _project(params, X, R)
    fiz = f * iz[:, None]  # (S, 2, N): f / z
    E = np.empty((S, 2, N, 7))
    # translation: d(x/z) = (dx - u dz) / z
    E[:, 0, :, 0] = fiz[:, 0]
    E[:, 0, :, 1] = 0.0
    E[:, 1, :, 0] = 0.0
    E[:, 1, :, 1] = fiz[:, 1]
    E[..., 2] = -uv * fiz
    # rotation: d(R X) = w x q for a small rotation w; with a = (1, 0, -u), b = (0, 1, -v)
    # du = a . (w x q) / z = (q x a) . w / z, and dv = (q x b) . w / z; w = W d(angles)
    Q = (q.mT @ _CROSS).reshape(S, 1, N, 3, 3)
    G = uv[..., None] * Q[..., 0, :] + Q[:, 0, :, 1:].swapaxes(1, 2)  # (S, 2, N, 3)
    E[..., 3:6] = (G.reshape(S, 2 * N, 3) @ W).reshape(S, 2, N, 3) * fiz[..., None]
    E[..., 6] = (uv - xy) * f
    E = E.reshape(S, 2 * N, 7)
    if behind:
        E[(iz == 0.0).any(axis=1), :, 6] = np.inf
    return E


def levenberg_marquardt(
    params: FloatArray, X: FloatArray, xy: FloatArray, f: FloatArray, *, max_iter: int, native: bool | None = None
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Refine S starts at once.

    Gauss-Newton steps (report Appendix G) with Marquardt's damping:
    ``(J^T J + lam diag(J^T J)) dx = -J^T r``; ``lam`` shrinks tenfold after a step that
    lowers the error and grows tenfold after one that does not (the step is then undone).
    A start stops when a step lowers its error, or the linear model predicts it would lower
    it, by less than :data:`RTOL` of it (plus :data:`ATOL`), or when ``lam`` exceeds 1e6.
    A start whose error is over 1.5 times the lowest one (a flip, or a start far from any
    minimum) stops at :data:`RTOL_OTHER`, and only the lowest start goes on after
    :data:`MAX_ITER_OTHER` iterations.

    Parameters
    ----------
    params : array_like (S, 6)
        Starting parameter vectors (see :func:`reprojection_residuals`); not modified.
    X, xy, f
        As for :func:`reprojection_residuals`, with N >= 1.
    max_iter : int
        Most iterations (>= 0; 0 evaluates ``sse`` and ``M`` at ``params``).
    native : bool or None
        Run the compiled version (``True``) or the numpy one (``False``); ``None``: the
        compiled one when it was built (:data:`NATIVE_LM`).

    Returns
    -------
    params : ndarray (S, 6)
        Refined parameter vectors.
    sse : ndarray (S,)
        Sum of squared residuals, px^2 (``inf`` for a start behind the camera).
    M : ndarray (S, 7, 7)
        ``E^T E`` at the result (see :func:`residuals_and_jacobian`): ``M[:, :6, :6]`` is
        ``J^T J``.

    Raises
    ------
    ValueError
        ``params`` not (S, 6), ``X`` not (3, N) with N >= 1, ``xy`` not (2, N), ``f`` not
        (2, 1), or ``max_iter`` not a whole number >= 0.
    RuntimeError
        ``native=True`` but the compiled version was not built.
    """
    x = np.array(params, dtype=np.float64)
    S = len(x)
    X = np.asarray(X, np.float64)
    xy = np.asarray(xy, np.float64)
    if x.ndim != 2 or x.shape[1] != 6:
        raise ValueError(f"params must have shape (S, 6), got {x.shape}")
    if X.ndim != 2 or X.shape[0] != 3 or X.shape[1] < 1 or xy.shape != (2, X.shape[1]):
        raise ValueError(f"X must be (3, N) with N >= 1 and xy (2, N), got {X.shape} and {xy.shape}")
    if np.shape(f) != (2, 1) or int(max_iter) != max_iter or max_iter < 0:
        raise ValueError(f"f must be (2, 1) and max_iter a whole number >= 0, got {np.shape(f)} and {max_iter!r}")
    if use_compiled(native, _lm, "visloc.pose._lm"):
        raw_x, raw_cost, raw_M = _lm.levenberg_marquardt(
            np.ascontiguousarray(x), np.ascontiguousarray(X, np.float64), np.ascontiguousarray(xy, np.float64),
            float(f[0, 0]), float(f[1, 0]), int(max_iter), RTOL, RTOL_OTHER, MAX_ITER_OTHER, ATOL)
        return (np.frombuffer(raw_x, np.float64).reshape(S, 6).copy(), np.frombuffer(raw_cost, np.float64).copy(),
                np.frombuffer(raw_M, np.float64).reshape(S, 7, 7).copy())
    return _lm_numpy(x, X, xy, f, max_iter)


def _damped_steps(M: FloatArray, lam: list[float], active: list[bool]) -> tuple[FloatArray, FloatArray]:
    """Marquardt's steps ``dx`` (S, 6, 1), solving ``(J^T J + lam diag(J^T J)) dx = J^T r``
    for every start from ``M = E^T E`` (S, 7, 7) and its damping ``lam`` (the new start is
    ``x - dx``), and ``J^T r`` (S, 6, 1); both zero for the starts no longer ``active``."""
    A = M[:, :6, :6]
    g = M[:, :6, 6:]  # J^T r
    damped = A + (A * _EYE6) * np.array(lam)[:, None, None]
    if not all(active):  # stopped starts (maybe behind the camera) take no step
        g = np.where(np.array(active)[:, None, None], g, 0.0)
        damped[[not a for a in active]] = _EYE6
    try:
        step = np.linalg.solve(damped, g)
    except np.linalg.LinAlgError:
        step = np.linalg.pinv(damped) @ g
    return step, g


def _lm_numpy(x: FloatArray, X: FloatArray, xy: FloatArray, f: FloatArray,
              max_iter: int) -> tuple[FloatArray, FloatArray, FloatArray]:
    """:func:`levenberg_marquardt` in numpy: the starts ``x`` (S, 6), refined in place, and
    their sums of squared residuals (S,), px^2, and ``E^T E`` (S, 7, 7) at the result."""
    S = len(x)
    E = residuals_and_jacobian(x, X, xy, f)
    M = E.mT @ E
    # bookkeeping in Python scalars: S is a handful
    cost = M[:, 6, 6].tolist()
    lam = [1e-3] * S
    active = [math.isfinite(c) for c in cost]
    for it in range(max_iter):
        step, g = _damped_steps(M, lam, active)
        # d.g: a lower bound of the decrease of the squared error that the linear model
        # predicts for the step d (d.g + lam d.diag(A).d; exactly d.g when undamped)
        pred = (step * g).sum(axis=(1, 2)).tolist()
        xn = x - step[..., 0]
        best = min(cost)
        rtol = [RTOL if c <= 1.5 * best else RTOL_OTHER for c in cost]
        for i in range(S):
            if active[i] and (
                pred[i] <= rtol[i] * cost[i] + ATOL or (it >= MAX_ITER_OTHER and cost[i] > best)
            ):
                active[i] = False  # another step would change (next to) nothing
        if not any(active):
            break
        Mn = residuals_and_jacobian(xn, X, xy, f)
        Mn = Mn.mT @ Mn
        cn = Mn[:, 6, 6].tolist()
        for i in range(S):
            if not active[i]:
                continue
            if cn[i] < cost[i]:  # False for nan
                if cost[i] - cn[i] <= rtol[i] * cost[i]:
                    active[i] = False
                x[i] = xn[i]
                M[i] = Mn[i]
                cost[i] = cn[i]
                lam[i] = max(lam[i] * 0.1, 1e-9)
            else:
                lam[i] *= 10.0
                if lam[i] > 1e6:
                    active[i] = False
    return x, np.array(cost), M


def refine_params(
    params: ArrayLike,
    object_points: ArrayLike,
    xy: ArrayLike,
    *,
    fx: float = 1.0,
    fy: float = 1.0,
    max_iter: int = 20,
) -> tuple[FloatArray, FloatArray]:
    """Minimise the reprojection error over ``[x y z phi theta psi]`` from one or more starts.

    Parameters
    ----------
    params : array_like (6,) or (S, 6)
        Starting parameter vectors ``[tx, ty, tz, phi, theta, psi]`` (object frame into
        camera frame, translation in the unit of ``object_points``, ``R = Rz(psi) Ry(theta)
        Rx(phi)`` in rad).
    object_points : array_like (N, 3)
        Points in the object frame (e.g. m), N >= 3.
    xy : array_like (N, 2)
        Their observed normalized image coordinates (undistorted, ``K^-1``).
    fx, fy : float
        Focal lengths, px: residuals are weighted as pixels (1 = normalized units).
    max_iter : int
        Most iterations.

    Returns
    -------
    params : ndarray, (6,) or (S, 6) as given
        Refined parameter vectors.
    sse : float or ndarray (S,)
        Sum of squared residuals (px^2 with ``fx, fy``); ``inf`` where a point ended behind
        the camera.

    Raises
    ------
    ValueError
        ``params`` not (6,) or (S, 6), ``object_points`` not (N, 3) with N >= 3, ``xy`` not
        (N, 2), or ``max_iter`` not a whole number >= 0.
    """
    x = np.array(params, dtype=np.float64)
    single = x.ndim == 1
    x = np.atleast_2d(x)
    if x.ndim != 2 or x.shape[1] != 6:
        raise ValueError(f"params must have shape (6,) or (S, 6), got {np.shape(params)}")
    X = np.asarray(object_points, dtype=np.float64)
    uv = np.asarray(xy, dtype=np.float64)
    if X.ndim != 2 or X.shape[1] != 3 or X.shape[0] < 3:
        raise ValueError(f"object_points must have shape (N, 3), N >= 3, got {X.shape}")
    if uv.shape != (X.shape[0], 2):
        raise ValueError(f"xy must have shape ({X.shape[0]}, 2), got {uv.shape}")
    if isinstance(max_iter, bool) or not isinstance(max_iter, numbers.Real) or max_iter < 0 or int(max_iter) != max_iter:
        raise ValueError(f"max_iter must be a whole number >= 0, got {max_iter!r}")
    f = np.array([[fx], [fy]], dtype=np.float64)
    x, sse, _ = levenberg_marquardt(x, X.T.copy(), uv.T.copy(), f, max_iter=int(max_iter))
    if single:
        return x[0], float(sse[0])
    return x, sse
