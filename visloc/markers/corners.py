"""Stages 6-7 of the marker pipeline: radial-peak corner split and total-least-squares line fits.

Report Appendix G (Figure G.1.D-F): the contour centre is the mean of its points; the distance
of every contour point to it, smoothed with a Gaussian kernel, peaks at the four corners; the
peaks split the contour into four groups, taken with a padding away from each peak to avoid the
corners rounded by the blur; a line is fitted to each group and the corners are the
intersections of consecutive lines.

Where the report special-cases near-vertical lines, the fit here is total least squares (the
line's normal is the covariance's minor eigenvector), which has no singular direction.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

_NEXT = np.array([1, 2, 3, 0])
_PREV = np.array([3, 0, 1, 2])

__all__ = [
    "RadialSplit",
    "fit_line",
    "fit_lines",
    "fit_quad",
    "intersect_lines",
    "orient_clockwise",
    "quad_from_lines",
    "radial_peaks",
    "radial_profile",
    "split_sides",
]


@dataclass(frozen=True, eq=False)
class RadialSplit:
    """Result of the radial-peak corner split of one contour.

    Attributes
    ----------
    center : ndarray (2,)
        Mean of the contour points.
    distance : ndarray (N,)
        Distance of every contour point to ``center``.
    smoothed : ndarray (N,)
        ``distance`` after circular Gaussian smoothing (taken at every
        :func:`profile_stride`-th point of long contours, interpolated between).
    peaks : ndarray (4,) int
        Contour indices of the four corners, in contour order.
    groups : list of ndarray
        Contour indices of the four sides' points (peak i to peak i+1, padded).
    """

    center: NDArray[np.float64]
    distance: NDArray[np.float64]
    smoothed: NDArray[np.float64]
    peaks: NDArray[np.intp]
    groups: list[NDArray[np.intp]]


def radial_profile(contour: NDArray, *, sigma: float | None = None) -> tuple[NDArray, NDArray, NDArray]:
    """Centre, point-to-centre distance and its circular Gaussian smoothing.

    Parameters
    ----------
    contour : ndarray (N, 2)
        Closed contour, ``(x, y)`` points in order, px.
    sigma : float, optional
        Smoothing in contour points; defaults to ``max(1, N / 100)``. The kernel reaches
        ``min(ceil(3 sigma), (N - 1) // 2)`` points to either side.

    Returns
    -------
    center : ndarray (2,) float64
        Mean of the contour points ``(x, y)``, px (report App. G).
    distance : ndarray (N,) float64
        Distance of every point to ``center``, px.
    smoothed : ndarray (N,) float64
        ``distance`` smoothed along the closed contour (a copy of it when the kernel would
        reach less than one point to either side).
    """
    pts = np.asarray(contour, np.float64)
    center = pts.mean(axis=0)  # report App. G: centre = mean of the contour pixels
    dist = np.hypot(pts[:, 0] - center[0], pts[:, 1] - center[1])
    n = len(dist)
    s = max(1.0, n / 100.0) if sigma is None else float(sigma)
    r = min(int(np.ceil(3 * s)), (n - 1) // 2)
    if r < 1:
        return center, dist, dist.copy()
    x = np.arange(-r, r + 1)
    k = np.exp(-0.5 * (x / s) ** 2)
    k /= k.sum()
    padded = np.concatenate([dist[-r:], dist, dist[:r]])  # circular: the contour is closed
    return center, dist, np.convolve(padded, k, mode="valid")


def radial_peaks(smoothed: NDArray, *, count: int = 4,
                 min_prominence: float | None = None) -> NDArray[np.intp] | None:
    """Indices of the ``count`` most significant maxima of a circular profile, in order.

    Maxima closer than ``N / 16`` points to a higher one are merged; of the rest, the
    ``count`` with the largest prominence (height above the higher of the two valleys that
    separate the peak from its neighbouring peaks) are kept.

    Parameters
    ----------
    smoothed : ndarray (N,)
        A circular profile, e.g. the smoothed distance of :func:`radial_profile` (px).
    count : int
        Number of maxima wanted (4: a quadrilateral's corners).
    min_prominence : float, optional
        Least prominence of a kept maximum, in the units of ``smoothed``; default 1 % of the
        profile's mean + 0.1.

    Returns
    -------
    ndarray (count,) intp or None
        Indices into ``smoothed``, ascending; ``None`` when fewer than ``count`` maxima rise
        at least ``min_prominence``.
    """
    d = np.round(np.asarray(smoothed, np.float64), 9)  # no peak decided by rounding noise
    n = len(d)
    prev = np.concatenate([d[-1:], d[:-1]])
    nxt = np.concatenate([d[1:], d[:1]])
    idx = np.flatnonzero((d > prev) & (d >= nxt))
    if len(idx) < count:
        return None
    order = idx[np.argsort(-d[idx])]
    min_gap = max(2, n // 16)
    chosen: list[int] = []
    for i in order.tolist():
        if all(min(abs(i - j), n - abs(i - j)) >= min_gap for j in chosen):
            chosen.append(i)
    if len(chosen) < count:
        return None
    ch = np.sort(np.array(chosen))
    start = ch[0]
    rolled = np.concatenate([d[start:], d[:start]])
    valley = np.minimum.reduceat(rolled, ch - start)  # segment k: peak k .. peak k+1
    prom = d[ch] - np.maximum(valley, np.concatenate([valley[-1:], valley[:-1]]))
    floor = 0.01 * d.mean() + 0.1 if min_prominence is None else min_prominence
    strong = prom >= floor
    if strong.sum() < count:
        return None
    ch, prom = ch[strong], prom[strong]
    if len(ch) > count:
        ch = np.sort(ch[np.argsort(-prom)[:count]])
    return ch.astype(np.intp)


def split_sides(n: int, peaks: NDArray[np.intp], *, padding: float = 0.1) -> list[NDArray[np.intp]]:
    """Contour indices of the four sides between consecutive ``peaks`` (circular).

    Parameters
    ----------
    n : int
        Number of points of the closed contour.
    peaks : ndarray (k,) int
        Contour indices of the corners in ascending order (:func:`radial_peaks`; k = 4).
    padding : float
        Fraction of each side's length dropped at both ends, plus one point, so the rounded
        corners do not bend the fitted lines (report App. G, Figure G.1.E).

    Returns
    -------
    list of k ndarray (M_i,) intp
        Side ``i``: the indices from ``peaks[i]`` to ``peaks[i + 1]`` (circular, mod ``n``)
        without the padding; empty when the side is too short.
    """
    groups = []
    for k in range(len(peaks)):
        a = int(peaks[k])
        b = int(peaks[(k + 1) % len(peaks)])
        length = (b - a) % n
        pad = int(padding * length) + 1
        groups.append((a + np.arange(pad, length - pad + 1)) % n)
    return groups


def fit_line(points: NDArray, weights: NDArray | None = None) -> NDArray[np.float64]:
    """Total-least-squares line through ``points``.

    The normal is the minor eigenvector of the (weighted) scatter matrix, so vertical lines
    need no special case.

    Parameters
    ----------
    points : ndarray (M, 2)
        ``(x, y)`` points, M >= 2.
    weights : ndarray (M,), optional
        Non-negative weights; 0 leaves a point out.

    Returns
    -------
    ndarray (3,) float64
        ``(a, b, c)`` with ``a x + b y = c`` and ``a^2 + b^2 = 1`` (the normal's sign is
        arbitrary), in the units of ``points``.

    Raises
    ------
    ValueError
        If ``points`` is not a 2-D array of at least 2 points.
    """
    p = np.asarray(points, np.float64)
    if p.ndim != 2 or len(p) < 2:
        raise ValueError(f"points must be (M >= 2, 2), got {p.shape}")
    return fit_lines(p[None], None if weights is None else np.asarray(weights)[None])[0]


def fit_lines(points: NDArray, weights: NDArray | None = None) -> NDArray[np.float64]:
    """Total-least-squares lines through K sets of points at once.

    Parameters
    ----------
    points : ndarray (K, M, 2)
        K sets of M ``(x, y)`` points.
    weights : ndarray (K, M), optional
        Non-negative weights; 0 leaves a point out (for sets of different sizes).

    Returns
    -------
    ndarray (K, 3) float64
        ``(a, b, c)`` per line, ``a x + b y = c``, unit normal ``(a, b)`` (its sign is
        arbitrary), in the units of ``points``.
    """
    p = np.asarray(points, np.float64)
    w = np.ones(p.shape[:2]) if weights is None else np.asarray(weights, np.float64)
    sw = np.maximum(w.sum(axis=1), 1e-12)
    x, y = p[..., 0], p[..., 1]
    mx = np.vecdot(w, x) / sw  # weighted centroid
    my = np.vecdot(w, y) / sw
    qx = x - mx[:, None]
    qy = y - my[:, None]
    wqx = w * qx
    sxx = np.vecdot(wqx, qx)
    syy = np.vecdot(w * qy, qy)
    sxy = np.vecdot(wqx, qy)
    theta = 0.5 * np.arctan2(2 * sxy, sxx - syy)  # direction of the major axis
    out = np.empty((len(p), 3))
    out[:, 0] = -np.sin(theta)
    out[:, 1] = np.cos(theta)
    out[:, 2] = out[:, 0] * mx + out[:, 1] * my
    return out


def intersect_lines(l1: NDArray, l2: NDArray) -> NDArray[np.float64]:
    """Intersection point of two lines.

    Parameters
    ----------
    l1, l2 : ndarray (3,)
        Lines ``(a, b, c)`` with ``a x + b y = c`` (:func:`fit_line`).

    Returns
    -------
    ndarray (2,) float64
        The point ``(x, y)``; NaN when the lines are parallel.
    """
    det = l1[0] * l2[1] - l1[1] * l2[0]
    if abs(det) < 1e-12:
        return np.array([np.nan, np.nan])
    x = (l1[2] * l2[1] - l1[1] * l2[2]) / det
    y = (l1[0] * l2[2] - l1[2] * l2[0]) / det
    return np.array([x, y])


def quad_from_lines(lines: NDArray) -> NDArray[np.float64]:
    """Corners of the quadrilaterals bounded by four lines in order.

    Parameters
    ----------
    lines : ndarray (..., 4, 3)
        Each quadrilateral's sides ``(a, b, c)``, ``a x + b y = c``, in order around it.

    Returns
    -------
    ndarray (..., 4, 2) float64
        Corner ``k`` is the intersection ``(x, y)`` of side k-1 and side k (NaN where two
        sides are parallel).
    """
    l1 = lines[..., _PREV, :]
    l2 = lines
    det = l1[..., 0] * l2[..., 1] - l1[..., 1] * l2[..., 0]
    det = np.where(np.abs(det) < 1e-12, np.nan, det)
    x = (l1[..., 2] * l2[..., 1] - l1[..., 1] * l2[..., 2]) / det
    y = (l1[..., 0] * l2[..., 2] - l1[..., 2] * l2[..., 0]) / det
    return np.stack([x, y], axis=-1)


def orient_clockwise(quad: NDArray) -> NDArray:
    """Return ``quad`` ordered clockwise in the image (y down), starting at its first corner.

    Parameters
    ----------
    quad : ndarray (4, 2)
        Corners ``(x, y)`` in image coordinates, in either direction around the quad.

    Returns
    -------
    ndarray (4, 2)
        ``quad`` itself when it is already clockwise, else its corners in the order 0, 3, 2, 1.
    """
    x, y = quad[:, 0], quad[:, 1]
    area2 = np.dot(x, y[_NEXT]) - np.dot(x[_NEXT], y)
    return quad if area2 > 0 else quad[[0, 3, 2, 1]]


def profile_stride(n: int | NDArray) -> int | NDArray:
    """Stride of the contour points the radial profile is taken at, for an ``n``-point contour
    (or for each of an array of contour lengths).

    At least 128 samples remain, a dozen or more per side: plenty for a profile smoothed over
    1 % of the contour, whose peaks only need to fall inside the padding that
    :func:`split_sides` leaves out next to each corner; and the cost of the smoothing and the
    peak search no longer grows with the marker's size.

    Parameters
    ----------
    n : int or ndarray of int
        Contour length(s), points.

    Returns
    -------
    int or ndarray of int
        The stride(s), >= 1: ``n // 128`` where that is larger.
    """
    return max(1, int(n) // 128) if np.isscalar(n) else np.maximum(1, np.asarray(n) // 128)


def fit_quad(
    contour: NDArray, *, sigma: float | None = None, padding: float = 0.1, hint: NDArray | None = None
) -> tuple[NDArray[np.float64], RadialSplit] | None:
    """Stages 6-7 for one contour: radial-peak split, line fits, corners at the intersections.

    The contour points are centres of the outermost ink pixels, half a pixel inside the
    ink's true edge; the lines are moved outward by 0.5 px to compensate.

    Parameters
    ----------
    contour : ndarray (N, 2)
        Closed border, ``(x, y)`` pixel centres (integer coordinates) in order
        (:func:`~visloc.markers.contours.enclosing_borders`).
    sigma : float, optional
        Smoothing of the radial profile in contour points; default ``max(1, N / 100)``
        (:func:`radial_profile`).
    padding : float
        Fraction of each side dropped at both ends (:func:`split_sides`).
    hint : ndarray (4, 2), optional
        Approximate corners ``(x, y)``, px (e.g. a polygon approximation) used when the radial profile
        has fewer than four significant peaks: an obtuse corner seen obliquely shows as a
        shoulder, not a peak, and on short contours pixel steps rival the corners'
        prominence.

    Returns
    -------
    (corners, split) or None
        Corners (4, 2) float64, ``(x, y)`` px (pixel centres at integer coordinates) on the
        ink's outer edge, clockwise in the image from the corner at the first peak (not yet
        the marker's own top-left: stage 10 finds that), and the split for inspection;
        ``None`` when no four corners could be found.
    """
    pts = np.asarray(contour, np.float64)
    n = len(pts)
    f = profile_stride(n)  # the profile at every f-th point (sigma in contour points)
    center, _, smooth_f = radial_profile(pts[::f], sigma=None if sigma is None else sigma / f)
    peaks = radial_peaks(smooth_f)
    if peaks is not None:
        peaks = peaks * f
    else:
        if hint is None:
            return None
        h = np.asarray(hint, np.float64)
        peaks = np.sort(np.argmin(((pts[None, :, :] - h[:, None, :]) ** 2).sum(-1), axis=1))
        if len(np.unique(peaks)) < 4:
            return None
    groups = split_sides(len(pts), peaks, padding=padding)
    sizes = [len(g) for g in groups]
    if min(sizes) < 2:
        return None
    m = max(sizes)
    idx = np.zeros((4, m), np.intp)
    w = np.zeros((4, m))
    for k, g in enumerate(groups):
        idx[k, : len(g)] = g
        w[k, : len(g)] = 1.0
    lines = fit_lines(pts[idx], w)
    # orient normals outward (away from the centre), then shift by 0.5 px
    inward = lines[:, 0] * center[0] + lines[:, 1] * center[1] > lines[:, 2]
    lines[inward] *= -1
    lines[:, 2] += 0.5
    corners = quad_from_lines(lines)
    if not np.isfinite(corners).all():
        return None
    dist = np.hypot(pts[:, 0] - center[0], pts[:, 1] - center[1])
    smooth = np.interp(np.arange(n), np.arange(0, n, f), smooth_f, period=n) if f > 1 else smooth_f
    split = RadialSplit(center, dist, smooth, peaks, groups)
    return orient_clockwise(corners), split
