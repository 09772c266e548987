"""Starting poses for a square marker seen at four normalized image points.

Two kinds of start:

* :func:`planar_solutions`: the two closed-form poses of a plane from its homography
  (infinitesimal plane-based pose estimation, IPPE), derived and written here. They sit in
  the two basins of the reprojection error of a square (the true pose and its "flip").
* :func:`yaw_seeds`: the report's four initial guesses of different yaw (Appendix G).

Inputs are normalized image coordinates ``xy`` (undistorted, ``K^-1``) of the corners in
OpenCV order; poses map marker-frame points into the camera frame (:mod:`visloc.types`).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from visloc.types import FloatArray

#: Marker corners in units of half the side, (x, y) in the marker frame, OpenCV order:
#: top-left, top-right, bottom-right, bottom-left (z = 0).
SQUARE = np.array([[-1.0, 1.0], [1.0, 1.0], [1.0, -1.0], [-1.0, -1.0]])

# report Appendix G: "four initial guesses are made in advance with each a different yaw"
_YAW_SEEDS = np.array([0.0, 0.5, 1.0, 1.5]) * math.pi


def marker_object_points(marker_length: float) -> FloatArray:
    """Corners of a marker in its own frame (OpenCV's ``SOLVEPNP_IPPE_SQUARE`` object points).

    Parameters
    ----------
    marker_length : float
        Side of the marker, m.

    Returns
    -------
    ndarray (4, 3)
        ``(-L/2, L/2, 0), (L/2, L/2, 0), (L/2, -L/2, 0), (-L/2, -L/2, 0)``, m, marker frame
        (centre origin, x right, y up, z out of the face), OpenCV corner order.
    """
    return np.column_stack([SQUARE * (0.5 * marker_length), np.zeros(4)])


def _centre_jacobian(xy: FloatArray) -> tuple[float, float, FloatArray]:
    """Image ``(u0, v0)`` of the marker centre and the Jacobian (2, 2) there of the
    homography from the marker plane (X, Y in half-sides) to the image, d(x, y)/d(X, Y).

    The projective map of the unit square onto the quadrilateral in closed form (Heckbert,
    "Fundamentals of texture mapping and image warping", 1989: square to quadrilateral),
    composed with ``(X, Y) -> (s, t) = ((X + 1) / 2, (1 - Y) / 2)``.
    """
    (x0, y0), (x1, y1), (x2, y2), (x3, y3) = xy.tolist()
    sx = x0 - x1 + x2 - x3
    sy = y0 - y1 + y2 - y3
    dx1, dx2, dy1, dy2 = x1 - x2, x3 - x2, y1 - y2, y3 - y2
    den = dx1 * dy2 - dx2 * dy1
    if den == 0.0:
        raise np.linalg.LinAlgError("collinear corners")
    g = (sx * dy2 - sy * dx2) / den
    h = (dx1 * sy - dy1 * sx) / den
    a, b = x1 - x0 + g * x1, x3 - x0 + h * x3
    d, e = y1 - y0 + g * y1, y3 - y0 + h * y3
    # x(s, t) = (a s + b t + x0) / (g s + h t + 1), y alike; the centre is s = t = 1/2
    w = 0.5 * (g + h) + 1.0
    if not w > 0.0:
        raise np.linalg.LinAlgError("degenerate homography")
    u0 = (0.5 * (a + b) + x0) / w
    v0 = (0.5 * (d + e) + y0) / w
    # chain rule: ds/dX = 1/2, dt/dY = -1/2
    J = np.array(
        [
            [0.5 * (a - u0 * g) / w, -0.5 * (b - u0 * h) / w],
            [0.5 * (d - v0 * g) / w, -0.5 * (e - v0 * h) / w],
        ]
    )
    return u0, v0, J


def planar_solutions(xy: ArrayLike, marker_length: float) -> tuple[FloatArray, FloatArray]:
    """The two closed-form poses of a square seen at normalized corners ``xy`` (4, 2).

    IPPE (Collins & Bartoli, "Infinitesimal plane-based pose estimation", IJCV 2014), at the
    marker centre: turn the camera by ``Rv`` so the centre's ray becomes the optical axis.
    There the homography's Jacobian ``J'`` is the upper-left 2x2 block ``B`` of the turned
    rotation divided by the depth. ``B``'s largest singular value is 1, which gives the
    depth; orthonormality of the first two columns fixes their third entries ``b`` up to a
    common sign (``b b^T = I - B^T B``): two rotations.

    Parameters
    ----------
    xy : array_like (4, 2)
        Normalized image coordinates of the corners, OpenCV order.
    marker_length : float
        Side of the marker, m.

    Returns
    -------
    R : ndarray (2, 3, 3)
        The two rotations, marker frame into camera frame (equal for a marker seen exactly
        face-on).
    t : ndarray (2, 3)
        The translations, m (the unit of ``marker_length``), camera frame; both put the
        centre on its ray at the depth from the Jacobian.

    Raises
    ------
    numpy.linalg.LinAlgError
        Degenerate (collinear, coincident) corners.
    """
    xy = np.asarray(xy, dtype=np.float64)
    u0, v0, J = _centre_jacobian(xy)
    n = math.sqrt(u0 * u0 + v0 * v0 + 1.0)
    ax, ay, c = u0 / n, v0 / n, 1.0 / n  # unit ray through the centre
    # Rv takes the ray onto e_z: Rodrigues with axis a x e_z = (ay, -ax, 0)
    k = 1.0 / (1.0 + c)
    Rv = np.array(
        [
            [1.0 - ax * ax * k, -ax * ay * k, -ax],
            [-ax * ay * k, 1.0 - ay * ay * k, -ay],
            [ax, ay, c],
        ]
    )
    # in the turned camera, d(x', y')/d(x, y) at the centre is Rv[:2, :2] / n
    (j00, j01), (j10, j11) = (Rv[:2, :2] @ J / n).tolist()
    fro2 = j00 * j00 + j01 * j01 + j10 * j10 + j11 * j11
    det = j00 * j11 - j01 * j10
    smax = math.sqrt(0.5 * (fro2 + math.sqrt(max(fro2 * fro2 - 4.0 * det * det, 0.0))))
    if not smax > 0.0:
        raise np.linalg.LinAlgError("degenerate homography")
    b00, b01, b10, b11 = j00 / smax, j01 / smax, j10 / smax, j11 / smax
    # b b^T = I - B^T B has rank one; take its column with the larger diagonal entry
    m00 = 1.0 - b00 * b00 - b10 * b10
    m11 = 1.0 - b01 * b01 - b11 * b11
    m01 = -(b00 * b01 + b10 * b11)
    e0 = e1 = 0.0
    if m00 >= m11 and m00 > 0.0:
        e0 = math.sqrt(m00)
        e1 = m01 / e0
    elif m11 > 0.0:
        e1 = math.sqrt(m11)
        e0 = m01 / e1
    Rp = np.empty((2, 3, 3))
    for i, sgn in enumerate((1.0, -1.0)):
        f0, f1 = sgn * e0, sgn * e1
        # columns r1 = (b00, b10, f0), r2 = (b01, b11, f1), r3 = r1 x r2
        Rp[i] = [
            [b00, b01, b10 * f1 - f0 * b11],
            [b10, b11, f0 * b01 - b00 * f1],
            [f0, f1, b00 * b11 - b10 * b01],
        ]
    R = Rv.T @ Rp
    depth = 0.5 * marker_length / smax  # the centre's depth along the turned optical axis
    t = np.array([ax, ay, c]) * depth
    return R, np.stack([t, t])


def yaw_seeds(xy: ArrayLike, marker_length: float) -> FloatArray:
    """The report's four initial guesses (Appendix G).

    The marker faces the camera (``phi = pi, theta = 0``: marker x right and y up in the
    image), turned by ``psi`` = 0, 90, 180 and 270 degrees about the optical axis, with its
    centre on the ray through the corners' mean at the depth where a face-on square of side
    ``marker_length`` covers the quadrilateral's area.

    Parameters
    ----------
    xy : array_like (4, 2)
        Normalized image coordinates (undistorted, ``K^-1``) of the corners, OpenCV order.
    marker_length : float
        Side of the marker, m.

    Returns
    -------
    ndarray (4, 6)
        Parameter vectors ``[x, y, z, phi, theta, psi]``: marker frame into camera frame,
        translation in m (the unit of ``marker_length``), angles in rad.

    Raises
    ------
    numpy.linalg.LinAlgError
        The corners enclose no area.
    """
    xy = np.asarray(xy, dtype=np.float64)
    (x0, y0), (x1, y1), (x2, y2), (x3, y3) = xy.tolist()
    area = 0.5 * abs((x2 - x0) * (y3 - y1) - (x3 - x1) * (y2 - y0))  # half the diagonals' cross
    if not area > 0.0:
        raise np.linalg.LinAlgError("corners enclose no area")
    d = marker_length / math.sqrt(area)
    seeds = np.empty((4, 6))
    seeds[:, 0] = 0.25 * d * (x0 + x1 + x2 + x3)
    seeds[:, 1] = 0.25 * d * (y0 + y1 + y2 + y3)
    seeds[:, 2] = d
    seeds[:, 3] = math.pi
    seeds[:, 4] = 0.0
    seeds[:, 5] = _YAW_SEEDS
    return seeds
