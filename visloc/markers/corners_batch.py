"""Stages 6-7 for many contours at once: :func:`fit_quads`, the batched :func:`fit_quad`.

The same algorithm as :func:`visloc.markers.corners.fit_quad` (report Appendix G, Figure
G.1.D-F: radial distance to the contour centre, circular Gaussian smoothing, the four most
significant peaks, padded side groups, total-least-squares lines, corners at their
intersections), written over a padded ``(K, N_max)`` array of all candidates of a frame so
that the per-candidate Python work disappears. Each step mirrors its single-contour
counterpart:

- :func:`radial_profile` at every :func:`~visloc.markers.corners.profile_stride`-th point:
  centre, distance, Gaussian smoothing with ``sigma = max(1, N / 100)`` (per contour) by
  gathering the ``2 r + 1`` circular neighbours;
- :func:`radial_peaks`: local maxima (``d > prev`` and ``d >= next``); greedy selection in
  height order with a circular gap of ``max(2, N // 16)``, done as "take the highest
  remaining maximum, drop the ones within the gap" until none remain; prominence above the
  higher of the two valleys between neighbouring chosen peaks; at least four above
  ``0.01 mean + 0.1``, the four most prominent kept;
- the polygon ``hint`` where that fails; :func:`split_sides`; :func:`fit_lines`.

The same steps compiled (``visloc.markers._quads``, built with the package) run one contour
after another without the padding and the per-step numpy calls, about ten times faster for a
frame's worth of candidates; both agree to about 1e-12 px. Without the compiled module the
numpy version here runs.
"""

from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import NDArray

from visloc._compiled import use_compiled
from visloc.markers.corners import _NEXT, RadialSplit, fit_lines, profile_stride, quad_from_lines

try:
    from visloc.markers import _quads
except ImportError:  # installed without a C compiler: the numpy version below
    _quads = None

#: Whether :func:`fit_quads` runs the compiled stages 6-7.
NATIVE_QUADS = _quads is not None

__all__ = ["NATIVE_QUADS", "fit_quads"]

_NEG = -np.inf


def _pack(contours: list[NDArray]) -> tuple[NDArray, NDArray, NDArray]:
    """Points (K, M, 2) wrapped circularly beyond each contour's length, lengths (K,), mask."""
    n = np.array([len(c) for c in contours])
    m = int(n.max())
    flat = np.concatenate([np.asarray(c).reshape(-1, 2) for c in contours]).astype(np.float64)
    start = np.concatenate([[0], np.cumsum(n)[:-1]])
    j = np.arange(m)
    idx = start[:, None] + j[None, :] % n[:, None]
    return flat[idx], n, j[None, :] < n[:, None]


def _circular(values: NDArray, n: NDArray, r: int) -> NDArray:
    """Read-only view (K, M, 2 r + 1) of ``values[k, (j + o) mod n_k]`` for o = -r .. r: each
    row extended circularly by r on both sides once, then windowed."""
    m = values.shape[1]
    ext = values[np.arange(len(values))[:, None], (np.arange(-r, m + r)[None, :]) % n[:, None]]
    return sliding_window_view(ext, 2 * r + 1, axis=1)


def _smooth(dist: NDArray, n: NDArray, sigma: float | NDArray | None) -> NDArray:
    """Circular Gaussian smoothing of each row (report App. G), as :func:`radial_profile`."""
    s = np.maximum(1.0, n / 100.0) if sigma is None else np.broadcast_to(np.asarray(sigma, np.float64), n.shape)
    r = np.minimum(np.ceil(3 * s).astype(int), (n - 1) // 2)
    rmax = int(r.max())
    if rmax < 1:
        return dist.copy()
    x = np.arange(-rmax, rmax + 1)
    k = np.exp(-0.5 * (x[None, :] / s[:, None]) ** 2) * (np.abs(x)[None, :] <= r[:, None])
    k /= k.sum(axis=1, keepdims=True)
    out = np.einsum("kmo,ko->km", _circular(dist, n, rmax), k)
    return np.where(r[:, None] >= 1, out, dist)


def _peaks(d: NDArray, n: NDArray, valid: NDArray, count: int = 4) -> tuple[NDArray, NDArray]:
    """Batched :func:`radial_peaks`: (K, 4) sorted peak indices and a (K,) success mask."""
    k, m = d.shape
    rows = np.arange(k)
    j = np.arange(m)
    prev = d[rows[:, None], (j[None, :] - 1) % n[:, None]]
    nxt = d[rows[:, None], (j[None, :] + 1) % n[:, None]]
    is_max = valid & (d > prev) & (d >= nxt)
    ok = is_max.sum(axis=1) >= count
    gap = np.maximum(2, n // 16)
    avail = np.where(is_max, d, _NEG)
    chosen = np.zeros((k, m), bool)
    while True:  # greedy in height order: take the highest, drop those within the gap
        best = np.argmax(avail, axis=1)
        live = avail[rows, best] > _NEG
        if not live.any():
            break
        chosen[rows[live], best[live]] = True
        circ = np.abs(j[None, :] - best[:, None])
        circ = np.minimum(circ, n[:, None] - circ)
        avail[(circ < gap[:, None]) & live[:, None]] = _NEG
    n_chosen = chosen.sum(axis=1)
    ok &= n_chosen >= count
    # prominence: segments from each chosen peak to the next (circular), rolled to start at the
    # first chosen peak of each row
    first = np.argmax(chosen, axis=1)
    pos = (first[:, None] + j[None, :]) % n[:, None]
    in_row = valid
    d_r = np.where(in_row, d[rows[:, None], pos], np.inf)
    seg = np.cumsum(chosen[rows[:, None], pos] & in_row, axis=1) - 1
    c_max = int(n_chosen.max()) if k else 0
    c_idx = np.arange(c_max)
    valley = np.where(seg[:, None, :] == c_idx[None, :, None], d_r[:, None, :], np.inf).min(axis=2)
    peak_pos = np.full((k, c_max), -1)
    rr, cc = np.nonzero(chosen[rows[:, None], pos] & in_row)
    peak_pos[rr, seg[rr, cc]] = pos[rr, cc]
    exists = c_idx[None, :] < n_chosen[:, None]
    prev_valley = valley[rows[:, None], (c_idx[None, :] - 1) % np.maximum(n_chosen, 1)[:, None]]
    height = np.where(exists, d[rows[:, None], np.maximum(peak_pos, 0)], _NEG)
    prom = height - np.maximum(valley, prev_valley)
    mean = np.where(valid, d, 0.0).sum(axis=1) / n
    strong = exists & (prom >= (0.01 * mean + 0.1)[:, None])
    ok &= strong.sum(axis=1) >= count
    rank = np.argsort(np.where(strong, -prom, np.inf), axis=1, kind="stable")[:, :count]
    if c_max < count:
        return np.zeros((k, count), np.intp), np.zeros(k, bool)
    peaks = np.sort(peak_pos[rows[:, None], rank], axis=1)
    return peaks.astype(np.intp), ok


def fit_quads(
    contours: list[NDArray],
    *,
    hints: NDArray | None = None,
    sigma: float | None = None,
    padding: float = 0.1,
    splits: bool = False,
    native: bool | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.bool_], list[RadialSplit | None] | None]:
    """Stages 6-7 for K contours: what :func:`visloc.markers.corners.fit_quad` does for one.

    Parameters
    ----------
    contours : list of ndarray (N_k, 2) int
        Closed contours, ``(x, y)`` pixel centres (integer coordinates) in order, at least 4
        points each (:func:`~visloc.markers.contours.find_candidates`).
    hints : ndarray (K, 4, 2), optional
        Approximate corners ``(x, y)`` per contour, px, used where the radial profile has
        fewer than four significant peaks (see :func:`~visloc.markers.corners.fit_quad`).
    sigma : float or None
        Smoothing of the radial profiles in contour points (> 0); ``None``:
        ``max(1, N_k / 100)`` per contour, as for :func:`~visloc.markers.corners.fit_quad`.
    padding : float
        Fraction of each side dropped at both ends, as for
        :func:`~visloc.markers.corners.fit_quad`.
    splits : bool
        Also return the :class:`RadialSplit` of each contour (for traces; computed by the numpy
        version).
    native : bool or None
        Run the compiled version (``True``) or the numpy one (``False``); ``None``: the
        compiled one when it was built (:data:`NATIVE_QUADS`).

    Returns
    -------
    corners : ndarray (K, 4, 2) float64
        Corners ``(x, y)``, px (pixel centres at integer coordinates), clockwise in the image
        as :func:`~visloc.markers.corners.fit_quad` gives them (NaN where ``ok`` is False).
    ok : ndarray (K,) bool
        Whether four corners were found.
    splits : list of RadialSplit or None, or None
        Per contour when ``splits`` is True.

    Raises
    ------
    ValueError
        If ``sigma`` is not > 0, or (compiled version) a contour has fewer than 4 points.
    RuntimeError
        If ``native=True`` and the compiled module was not built.
    """
    k = len(contours)
    if k == 0:
        return np.zeros((0, 4, 2)), np.zeros(0, bool), [] if splits else None
    if sigma is not None and not sigma > 0:
        raise ValueError(f"sigma must be > 0 (or None), got {sigma}")
    if not use_compiled(native, _quads, "visloc.markers._quads"):
        return _fit_quads_numpy(contours, hints, sigma, padding, splits)
    lengths = np.array([len(c) for c in contours], np.int64)
    if (lengths < 4).any():
        raise ValueError(f"contours need at least 4 points each, got {int(lengths.min())}")
    pts = np.ascontiguousarray(np.concatenate([np.asarray(c).reshape(-1, 2) for c in contours]), np.int32)
    offsets = np.concatenate([[0], np.cumsum(lengths)])
    h = None if hints is None else np.ascontiguousarray(np.asarray(hints, np.float64).reshape(k, 4, 2))
    raw, raw_ok = _quads.fit_quads(pts, offsets, h, 0.0 if sigma is None else float(sigma), float(padding))
    corners = np.frombuffer(raw, np.float64).reshape(k, 4, 2).copy()
    ok = np.frombuffer(raw_ok, np.uint8).astype(bool)
    out_splits = _fit_quads_numpy(contours, hints, sigma, padding, True)[2] if splits else None
    return corners, ok, out_splits


def _fit_quads_numpy(contours: list[NDArray], hints: NDArray | None, sigma: float | None, padding: float,
                     splits: bool) -> tuple[NDArray[np.float64], NDArray[np.bool_], list[RadialSplit | None] | None]:
    """:func:`fit_quads` in numpy over a padded (K, N_max) array of all the contours."""
    k = len(contours)
    pts, n, valid = _pack(contours)
    rows = np.arange(k)
    # the radial profile at every f-th point (corners.profile_stride)
    f = profile_stride(n)
    nf = (n + f - 1) // f
    jf = np.arange(int(nf.max()))
    pts_f = pts[rows[:, None], (jf[None, :] * f[:, None]) % n[:, None]]
    valid_f = jf[None, :] < nf[:, None]
    center = np.where(valid_f[..., None], pts_f, 0.0).sum(axis=1) / nf[:, None]  # report App. G
    dist = np.hypot(pts_f[..., 0] - center[:, 0:1], pts_f[..., 1] - center[:, 1:2])
    smooth = _smooth(dist, nf, None if sigma is None else sigma / f)
    peaks, ok = _peaks(np.round(smooth, 9), nf, valid_f)  # as radial_peaks: no peak decided by rounding noise
    peaks = peaks * f[:, None]
    if hints is not None:
        h = np.asarray(hints, np.float64)
        miss = ~ok
        if miss.any():
            d2 = ((pts[miss][:, None, :, :] - h[miss][:, :, None, :]) ** 2).sum(-1)
            d2 = np.where(valid[miss][:, None, :], d2, np.inf)
            near = np.sort(np.argmin(d2, axis=2), axis=1)
            distinct = (np.diff(near, axis=1) > 0).all(axis=1)
            peaks[miss] = near
            ok[miss] = distinct
    # side groups between consecutive peaks, padded (split_sides)
    a = peaks
    b = peaks[:, [1, 2, 3, 0]]
    length = (b - a) % n[:, None]
    pad = (padding * length).astype(int) + 1
    size = length - 2 * pad + 1
    ok &= (size >= 2).all(axis=1)
    width = max(int(size.max()), 2)
    off = np.arange(width)
    idx = (a[..., None] + pad[..., None] + off) % n[:, None, None]
    w = (off[None, None, :] < size[..., None]).astype(np.float64)
    lines = fit_lines(pts[rows[:, None, None], idx].reshape(-1, width, 2), w.reshape(-1, width))
    lines = lines.reshape(k, 4, 3)
    inward = lines[..., 0] * center[:, None, 0] + lines[..., 1] * center[:, None, 1] > lines[..., 2]
    lines[inward] *= -1  # normals outward, then half a pixel out to the ink edge (fit_quad)
    lines[..., 2] += 0.5
    corners = quad_from_lines(lines)
    ok &= np.isfinite(corners).all(axis=(1, 2))
    x, y = corners[..., 0], corners[..., 1]
    ccw = (x * y[:, _NEXT]).sum(1) - (x[:, _NEXT] * y).sum(1) <= 0
    corners[ccw] = corners[ccw][:, [0, 3, 2, 1]]  # orient_clockwise
    corners[~ok] = np.nan
    out_splits = None
    if splits:
        out_splits = []
        for i in range(k):
            if not ok[i]:
                out_splits.append(None)
                continue
            ni = int(n[i])
            groups = [(int(a[i, s]) + np.arange(int(pad[i, s]), int(length[i, s]) - int(pad[i, s]) + 1)) % ni
                      for s in range(4)]
            fi = int(f[i])
            full = np.hypot(pts[i, :ni, 0] - center[i, 0], pts[i, :ni, 1] - center[i, 1])
            sm = smooth[i, : int(nf[i])]
            sm = np.interp(np.arange(ni), np.arange(0, ni, fi), sm, period=ni) if fi > 1 else sm.copy()
            out_splits.append(RadialSplit(center[i], full, sm, peaks[i].copy(), groups))
    return corners, ok, out_splits
