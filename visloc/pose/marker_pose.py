"""Pose of one square marker from its four image corners.

The report (§3.2.2, Appendix G) estimates the pose with a Gauss-Newton iteration on the
reprojection error over ``[x y z phi theta psi]``, started from the best of four initial
guesses of different yaw. :func:`estimate_marker_pose` keeps the iteration and adds the two
closed-form planar solutions (:func:`visloc.pose.planar.planar_solutions`) as starts: a
square has two minima of the reprojection error (the pose and its "flip") and the planar
solutions sit one in each, while a face-on yaw guess can end in either.

Corners are undistorted once; everything after works in normalized image coordinates with
residuals weighted back into pixels by ``fx, fy``.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from visloc.pose.camera import Camera
from visloc.pose.gauss_newton import (
    levenberg_marquardt,
    reprojection_residuals,
    rotations_and_rates,
)
from visloc.pose.planar import SQUARE, marker_object_points, planar_solutions, yaw_seeds
from visloc.pose.rotations import matrix_to_euler, matrix_to_euler_list, rotation_angle
from visloc.types import FloatArray, Pose

#: Pixel noise (px) assumed for ``covariance`` when ``pixel_sigma`` is not given and the
#: residual estimate is smaller (exact corners): a good sub-pixel corner detector's level.
MIN_PIXEL_SIGMA = 0.05

#: Two refined solutions whose rotations differ by less than this (rad) are one pose.
SAME_POSE_RAD = 1e-3

#: Values of ``estimate_marker_pose(start=...)``.
STARTS = ("auto", "planar", "yaw", "all")

_ONE = np.ones((2, 1))
_SQUARE_T = np.vstack([SQUARE.T, np.zeros((1, 4))])  # (3, 4) corners in half-sides


def yaw_seed_start(xy: ArrayLike, marker_length: float) -> FloatArray:
    """The best of the report's four yaw guesses (:func:`~visloc.pose.planar.yaw_seeds`):
    "the guess with the smallest error is used as the initial value for the iterative
    optimization process" (report Appendix G).

    Parameters
    ----------
    xy : array_like (4, 2)
        Normalized image coordinates (undistorted, ``K^-1``) of the corners, OpenCV order;
        the reprojection error is measured in these normalized units.
    marker_length : float
        Side of the marker, m.

    Returns
    -------
    ndarray (6,)
        ``[x y z phi theta psi]``: marker frame into camera frame, m and rad.

    Raises
    ------
    numpy.linalg.LinAlgError
        The corners enclose no area.
    """
    xy = np.asarray(xy, dtype=np.float64)
    seeds = yaw_seeds(xy, marker_length)
    X = marker_object_points(marker_length).T.copy()
    r = reprojection_residuals(seeds, X, xy.T.copy(), _ONE)
    return seeds[int(np.argmin((r * r).sum(axis=1)))]


def _checked_corners(corners: ArrayLike) -> FloatArray:
    """:func:`estimate_marker_pose`'s corners as (4, 2) float64, checked (its Raises)."""
    raw = np.asarray(corners)
    if raw.dtype.kind in "iub" and raw.dtype.itemsize < 4:
        raise TypeError(f"corners of dtype {raw.dtype} cannot hold pixel coordinates (they wrap): pass floats")
    c = np.asarray(corners, dtype=np.float64)
    if c.shape != (4, 2):
        if c.size == 8 and c.squeeze().shape == (4, 2):
            c = c.reshape(4, 2)
        else:
            raise ValueError(f"corners must have shape (4, 2), got {np.shape(corners)}")
    if not np.all(np.isfinite(c)):
        raise ValueError(f"corners must be finite, got {c.tolist()}")
    if not _is_proper_quadrilateral(c):
        raise ValueError(
            f"corners are degenerate (coincident, or three of them collinear): {c.tolist()}"
        )
    x, y = c[:, 0], c[:, 1]
    if np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y) < 0:  # twice the signed area, y down
        raise ValueError("corners run counter-clockwise in the image (a mirrored marker): the order is the "
                         f"marker's top-left, top-right, bottom-right, bottom-left, clockwise: {c.tolist()}")
    return c


def _check_options(marker_length: float, camera: Camera, pixel_sigma: float | None, max_iter: int,
                   start: str) -> None:
    """:func:`estimate_marker_pose`'s other arguments checked (its Raises)."""
    if isinstance(marker_length, bool) or not isinstance(marker_length, (int, float, np.number)):
        raise TypeError(f"marker_length must be a number, got {type(marker_length).__name__}")
    if not (math.isfinite(marker_length) and marker_length > 0):
        raise ValueError(f"marker_length must be a finite number > 0, got {marker_length!r}")
    if not isinstance(camera, Camera):
        raise TypeError(f"camera must be a visloc.pose.Camera, got {type(camera).__name__}")
    if pixel_sigma is not None and not (math.isfinite(pixel_sigma) and pixel_sigma > 0):
        raise ValueError(f"pixel_sigma must be None or a finite number > 0, got {pixel_sigma!r}")
    if isinstance(max_iter, bool) or int(max_iter) != max_iter or max_iter < 1:
        raise ValueError(f"max_iter must be an integer >= 1, got {max_iter!r}")
    if start not in STARTS:
        raise ValueError(f"start must be one of {STARTS}, got {start!r}")


def estimate_marker_pose(
    corners: ArrayLike,
    marker_length: float,
    camera: Camera,
    *,
    pixel_sigma: float | None = None,
    max_iter: int = 20,
    start: str = "auto",
) -> Pose:
    """Pose of a square marker (marker frame into camera frame) from its image corners.

    Parameters
    ----------
    corners : array_like (4, 2)
        Pixel corners in OpenCV order: the marker's top-left, top-right, bottom-right,
        bottom-left. OpenCV's (1, 4, 2) is accepted too.
    marker_length : float
        Side of the marker's square, m.
    camera : Camera
        Intrinsics; the corners are undistorted once.
    pixel_sigma : float, optional
        Standard deviation of the corner noise per coordinate, px, for ``covariance``.
        Default: estimated from the residuals, ``sqrt(SSE / (8 - 6))``, but at least
        :data:`MIN_PIXEL_SIGMA`. With two degrees of freedom that estimate is rough: pass
        the detector's noise level when it is known.
    max_iter : int
        Most Gauss-Newton (Levenberg-Marquardt) iterations.
    start : {"auto", "planar", "yaw", "all"}
        Starting poses: ``"planar"`` the two closed-form planar solutions; ``"yaw"`` only
        the best of the report's four yaw guesses (Appendix G, as the report does it; then
        ``alternative`` is ``None``); ``"all"`` both kinds; ``"auto"`` (default) the planar
        solutions, with the yaw guess as a fallback when they are degenerate or end behind
        the camera.

    Returns
    -------
    Pose
        ``R, t`` with ``p_cam = R @ p_marker + t``; ``reprojection_rms``: RMS corner
        distance, px, in the undistorted image; ``covariance``: (6, 6) of
        ``[tx ty tz phi theta psi]`` (``Pose.params``) = ``sigma^2 (J^T J)^-1`` with ``J``
        in px, or ``None`` when singular (marker seen edge-on); ``alternative``: the other
        refined solution (the flip), ``None`` when it coincides with the pose (marker
        face-on) or is not in front of the camera; ``alternative_rms``: its RMS.

    Raises
    ------
    ValueError
        ``corners`` not (4, 2), not finite, degenerate (no pose fits) or counter-clockwise in
        the image (a marker seen mirrored, which no camera sees); ``marker_length`` not finite
        and > 0; bad ``pixel_sigma``, ``max_iter`` or ``start``.
    TypeError
        ``camera`` is not a :class:`Camera`; ``marker_length`` is not a number; ``corners``
        of an integer type too narrow for pixel coordinates (8 or 16 bits).
    """
    c = _checked_corners(corners)
    _check_options(marker_length, camera, pixel_sigma, max_iter, start)
    L = float(marker_length)
    max_iter = int(max_iter)

    xy = camera.normalize(c)  # undistort once; normalized coordinates from here on
    X = _SQUARE_T * (0.5 * L)
    xyT = xy.T.copy()
    f = np.array([[camera.fx], [camera.fy]])

    starts, with_yaw = _starts(xy, L, c, start)
    # report §3.2.2 / App. G: Gauss-Newton on the reprojection error over [x y z phi theta psi]
    params, sse, M = levenberg_marquardt(np.array(starts), X, xyT, f, max_iter=max_iter)
    if start == "auto" and not with_yaw and not np.isfinite(sse).any():
        # the planar solutions ended behind the camera: fall back on the report's yaw guess
        params, sse, M = levenberg_marquardt(_yaw_start(xy, L, c)[None], X, xyT, f, max_iter=max_iter)
    if not np.isfinite(sse).any():
        raise ValueError(f"no pose puts all corners in front of the camera: {c.tolist()}")
    params, M = _on_pose_branch(params, M, X, xyT, f)
    return _best_poses(params, sse, M, pixel_sigma)


def _starts(xy: FloatArray, L: float, c: FloatArray, start: str) -> tuple[list[list[float]], bool]:
    """:func:`estimate_marker_pose`'s starting parameter vectors ``[x y z phi theta psi]`` for
    its ``start`` from the normalized corners ``xy`` (4, 2) of a marker of side ``L`` (m),
    and whether the yaw guess is among them (``c``: the pixel corners, for the errors)."""
    starts = []
    if start != "yaw":
        try:
            Rs, ts = planar_solutions(xy, L)
            starts += [[*tk, *ek] for tk, ek in zip(ts.tolist(), matrix_to_euler_list(Rs))]
        except np.linalg.LinAlgError:
            if start == "planar":
                raise ValueError(f"corners are degenerate: {c.tolist()}") from None
    with_yaw = start in ("yaw", "all") or (start == "auto" and not starts)
    if with_yaw:
        starts.append(_yaw_start(xy, L, c))  # report App. G: best of four yaw guesses
    return starts, with_yaw


def _on_pose_branch(params: FloatArray, M: FloatArray, X: FloatArray, xyT: FloatArray,
                    f: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The refined ``params`` (S, 6), their angles moved (in place) onto the branch of
    ``Pose.params``, and ``M`` (S, 7, 7) re-evaluated there when any moved (``X``, ``xyT``
    and ``f`` as for :func:`levenberg_marquardt`)."""
    # Pose.params uses the branch theta in [-pi/2, pi/2]; the covariance must match it
    if (np.cos(params[:, 4]) < 0.0).any():
        params[:, 3:] = matrix_to_euler(rotations_and_rates(params)[0])
        _, _, M = levenberg_marquardt(params, X, xyT, f, max_iter=0)
    return params, M


def _best_poses(params: FloatArray, sse: FloatArray, M: FloatArray, pixel_sigma: float | None) -> Pose:
    """The refined solution of least ``sse`` as a :class:`Pose`, with as its alternative the
    next one whose rotation differs from it by more than :data:`SAME_POSE_RAD` (if any);
    ``params`` (S, 6), ``sse`` (S,) px^2, ``M`` (S, 7, 7) as from :func:`levenberg_marquardt`."""
    R = rotations_and_rates(params)[0]
    order = [int(i) for i in np.argsort(sse, kind="stable") if np.isfinite(sse[i])]
    chosen = order[:1]
    for i in order[1:]:
        if rotation_angle(R[order[0]].T @ R[i]) > SAME_POSE_RAD:
            chosen.append(i)
            break
    rms = [_rms(sse[i]) for i in chosen]
    cov = _covariances(M[chosen], pixel_sigma)
    alternative = None
    if len(chosen) == 2:
        i = chosen[1]
        alternative = Pose(R[i], params[i, :3].copy(), rms[1], cov[1])
    i = chosen[0]
    return Pose(
        R[i],
        params[i, :3].copy(),
        rms[0],
        cov[0],
        alternative,
        None if alternative is None else rms[1],
    )


def _is_proper_quadrilateral(corners: FloatArray) -> bool:
    """No two consecutive corners coincide and no three consecutive ones are collinear
    (sine of the corner angle above 1e-9): what any view of a square not seen edge-on gives."""
    p = corners.tolist()
    for k in range(4):
        (ax, ay), (bx, by), (cx, cy) = p[k - 1], p[k], p[(k + 1) % 4]
        ux, uy, vx, vy = bx - ax, by - ay, cx - bx, cy - by
        norms = math.hypot(ux, uy) * math.hypot(vx, vy)
        if not abs(ux * vy - uy * vx) > 1e-9 * norms:
            return False
    return True


def _yaw_start(xy: FloatArray, marker_length: float, corners: FloatArray) -> FloatArray:
    try:
        return yaw_seed_start(xy, marker_length)
    except np.linalg.LinAlgError:
        raise ValueError(
            f"corners are degenerate (they enclose no area): {corners.tolist()}"
        ) from None


def _rms(sse: float) -> float:
    return math.sqrt(float(sse) / 4.0)  # RMS of the four corner distances


def _covariances(M: FloatArray, pixel_sigma: float | None) -> list[FloatArray | None]:
    """``sigma^2 (J^T J)^-1`` for each ``M = [J | r]^T [J | r]`` (K, 7, 7); ``None`` where
    ``J^T J`` is singular (the marker seen edge-on)."""
    if pixel_sigma is None:
        # unbiased per-coordinate variance SSE / (8 residuals - 6 parameters), floored
        var = np.maximum(M[:, 6, 6] / 2.0, MIN_PIXEL_SIGMA**2)
    else:
        var = np.full(len(M), float(pixel_sigma) ** 2)
    try:
        inv = np.linalg.inv(M[:, :6, :6])
    except np.linalg.LinAlgError:
        inv = np.full((len(M), 6, 6), np.nan)
        for k in range(len(M)):
            try:
                inv[k] = np.linalg.inv(M[k, :6, :6])
            except np.linalg.LinAlgError:
                pass
    cov = var[:, None, None] * 0.5 * (inv + inv.mT)
    ok = np.isfinite(cov).all(axis=(1, 2)) & (np.diagonal(cov, axis1=1, axis2=2) > 0).all(1)
    return [cov[k] if ok[k] else None for k in range(len(M))]


def pose_error(pose: Pose, R_true: ArrayLike, t_true: ArrayLike) -> tuple[float, float]:
    """Rotation and translation error of ``pose`` against a known true pose.

    Parameters
    ----------
    pose : Pose
        Estimated pose (e.g. ``T_cam_marker``).
    R_true : array_like (3, 3)
        True rotation, same frames as ``pose.R``.
    t_true : array_like (3,)
        True translation, same frames and unit as ``pose.t`` (e.g. m); any shape of 3 entries.

    Returns
    -------
    rotation_error : float
        Angle of ``R^T R_true``, rad, in [0, pi].
    translation_error : float
        ``|t - t_true|``, in the unit of ``t`` (m for visloc's poses).

    Raises
    ------
    ValueError
        ``R_true`` not (3, 3) or ``t_true`` without 3 entries.
    """
    R_true = np.asarray(R_true, dtype=np.float64)
    t_true = np.asarray(t_true, dtype=np.float64)
    if R_true.shape != (3, 3):
        raise ValueError(f"R_true must have shape (3, 3), got {R_true.shape}")
    if t_true.size != 3:
        raise ValueError(f"t_true must have 3 entries, got shape {t_true.shape}")
    return rotation_angle(pose.R.T @ R_true), float(np.linalg.norm(pose.t - t_true.reshape(3)))


def is_flip(pose: Pose, R_true: ArrayLike) -> bool:
    """Whether ``pose`` took the wrong planar solution.

    Parameters
    ----------
    pose : Pose
        Estimated pose with its ``alternative`` (:func:`estimate_marker_pose`).
    R_true : array_like (3, 3)
        True rotation, same frames as ``pose.R``.

    Returns
    -------
    bool
        True when ``pose.alternative`` is closer in rotation to ``R_true`` than the pose
        itself; False when there is no alternative.

    Raises
    ------
    ValueError
        ``R_true`` not (3, 3) (when ``pose`` has an alternative).
    """
    if pose.alternative is None:
        return False
    R_true = np.asarray(R_true, dtype=np.float64)
    return rotation_angle(pose.alternative.R.T @ R_true) < rotation_angle(pose.R.T @ R_true)


__all__ = [
    "MIN_PIXEL_SIGMA",
    "SAME_POSE_RAD",
    "STARTS",
    "estimate_marker_pose",
    "is_flip",
    "pose_error",
    "yaw_seed_start",
]
