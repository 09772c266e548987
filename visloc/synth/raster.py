"""Exact anti-aliased rasterisation of polygons (area coverage per pixel).

The renderers need images whose geometry is known to a small fraction of a pixel. Point
sampling, even supersampled, quantises an edge's position to the sample spacing; here every
pixel instead gets the exact area of its square covered by the polygons, computed in closed
form from the polygon edges. The result is exact up to floating-point rounding (~1e-9 px).

Method: the coverage of pixel ``(row, j)`` by a polygon is the integral over the pixel square
of the winding number, which is a sum over edges of ``int clamp(j + 1 - x_e(y), 0, 1) dy``
over the part of edge ``e`` inside the row (coordinates shifted so the pixel covers
``[j, j + 1] x [row, row + 1]``). Along one edge ``x_e`` is linear in ``y``, so the integral
has the closed form ``dy * (Q(j + 1 - x_a) - Q(j + 1 - x_b)) / (x_b - x_a)`` with ``Q`` the
antiderivative of ``clamp(z, 0, 1)``. Differences of this along ``j`` are scattered into an
accumulation buffer and a cumulative sum along each row yields the coverage (the scheme of
font rasterisers, with the per-column areas in closed form).

Coordinates follow :mod:`visloc.types`: the centre of pixel ``(col, row)`` is at ``(col, row)``
and the pixel covers ``[col - 0.5, col + 0.5] x [row - 0.5, row + 0.5]``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

_FLAT = 1e-6  # below this x-extent (px) a row piece is treated as vertical (error < 1e-6 px)


def polygon_edges(
    polygons: Sequence[FloatArray], weights: Sequence[float]
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Collect the edges of closed polygons, oriented so each adds ``+weight`` inside.

    Parameters
    ----------
    polygons : sequence of ndarray (n_i, 2)
        Simple polygons in image coordinates (pixel centres at integers), either orientation.
    weights : sequence of float
        Value each polygon adds to the pixels it covers (negative to cut holes).

    Returns
    -------
    start, end : ndarray (E, 2)
        Edge end points.
    weight : ndarray (E,)
        Weight of each edge, signed so that :func:`edge_coverage` adds ``+weight`` inside.

    Raises
    ------
    ValueError
        If ``polygons`` and ``weights`` differ in length, or a polygon is not (n, 2).
    """
    polys = [np.asarray(poly, np.float64) for poly in polygons]
    polys = [q.reshape(0, 2) if q.size == 0 else q for q in polys]
    if any(q.ndim != 2 or q.shape[1] != 2 for q in polys):
        raise ValueError("polygons: each must be an (n, 2) array of vertices")
    w = np.array([float(v) for v in weights], np.float64)
    if len(w) != len(polys):
        raise ValueError(f"polygons and weights differ in length: {len(polys)} and {len(w)}")
    sizes = np.array([len(q) for q in polys], np.int64)
    kept = sizes >= 3
    if not kept.any():
        empty = np.zeros((0, 2))
        return empty, empty.copy(), np.zeros(0)
    p = np.concatenate([q for q, k in zip(polys, kept.tolist(), strict=True) if k])
    n = sizes[kept]
    first = np.cumsum(n) - n
    nxt = np.arange(len(p)) + 1  # each vertex's next one, the last back to its polygon's first
    nxt[first + n - 1] = first
    q = p[nxt]
    twice_area = np.add.reduceat(p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1], first)  # (the same sums, in order)
    edge_weight = np.repeat(-w[kept] * np.sign(twice_area), n)
    nonzero = np.repeat(twice_area != 0.0, n)  # degenerate polygons add nothing
    return p[nonzero], q[nonzero], edge_weight[nonzero]


def _ramp_integral(z: FloatArray) -> FloatArray:
    """Antiderivative of ``clamp(z, 0, 1)`` that vanishes for ``z <= 0``."""
    return np.where(z <= 0.0, 0.0, np.where(z < 1.0, 0.5 * z * z, z - 0.5))


def edge_coverage(
    start: FloatArray, end: FloatArray, weight: FloatArray, shape: tuple[int, int]
) -> FloatArray:
    """Sum of the weighted exact pixel coverages of the polygons the edges bound.

    Parameters
    ----------
    start, end : ndarray (E, 2)
        Edge end points ``(x, y)``, px, pixel centres at integer coordinates, from
        :func:`polygon_edges`; together they must form closed polygons. Coordinates may lie
        far outside the image.
    weight : ndarray (E,)
        Edge weights from :func:`polygon_edges`.
    shape : (int, int)
        ``(height, width)`` of the output.

    Returns
    -------
    ndarray (height, width) float64
        ``sum_k w_k * area(pixel ∩ polygon_k)`` for every pixel (pixel area 1).
    """
    return window_coverages(start, end, weight, np.zeros(len(weight), np.int64), [shape])[0]


def window_coverages(start: FloatArray, end: FloatArray, weight: FloatArray, window: NDArray[np.int64],
                     shapes: Sequence[tuple[int, int]]) -> list[FloatArray]:
    """:func:`edge_coverage` of several pixel grids at once: edge ``e`` belongs to grid
    ``window[e]`` (its coordinates in that grid's pixels), and grid ``i`` is ``shapes[i]``
    ``(height, width)``. Each grid's coverage is what :func:`edge_coverage` gives for its own
    edges alone, to the bit (the same operations on each edge, and each pixel's sum taken
    over the same terms in the same order), in one pass of array operations for all grids.

    Parameters
    ----------
    start, end : ndarray (E, 2)
        Edge end points, px (as :func:`edge_coverage`).
    weight : ndarray (E,)
        Edge weights.
    window : ndarray (E,) int
        Index into ``shapes`` of each edge's grid.
    shapes : sequence of (int, int)
        ``(height, width)`` of each grid.

    Returns
    -------
    list of ndarray (height_i, width_i) float64
        The coverage of each grid, in the order of ``shapes``.
    """
    dims = np.array(shapes, np.int64).reshape(-1, 2)
    heights, widths = dims[:, 0], dims[:, 1]
    sizes = heights * (widths + 1)  # column w collects contributions that only reach pixels right of the grid
    bases = np.cumsum(sizes) - sizes
    x0, y0 = start[:, 0] + 0.5, start[:, 1] + 0.5
    x1, y1 = end[:, 0] + 0.5, end[:, 1] + 0.5
    keep = (y0 != y1) & (weight != 0.0)
    x0, y0, x1, y1, wt, win = x0[keep], y0[keep], x1[keep], y1[keep], weight[keep], np.asarray(window)[keep]
    total = int(sizes.sum())
    acc = _accumulate(x0, y0, x1, y1, wt, win, heights, widths, bases, total) if x0.size else np.zeros(total)
    return [np.cumsum(acc[b: b + hw].reshape(h, w + 1), axis=1)[:, :w]
            for b, hw, h, w in zip(bases.tolist(), sizes.tolist(), heights.tolist(), widths.tolist(), strict=True)]


def _accumulate(x0: FloatArray, y0: FloatArray, x1: FloatArray, y1: FloatArray, wt: FloatArray,
                win: NDArray[np.int64], heights: NDArray[np.int64], widths: NDArray[np.int64],
                bases: NDArray[np.int64], total: int) -> FloatArray:
    """The flat accumulation buffer of :func:`window_coverages` (before the sums along each
    row) for edges ``(x0, y0) -> (x1, y1)`` shifted by half a pixel, none horizontal."""
    h_e = heights[win]
    # Split every edge into pieces, one per pixel row it crosses.
    ylo, yhi = np.minimum(y0, y1), np.maximum(y0, y1)
    r_first = np.clip(np.floor(ylo), 0, h_e).astype(np.int64)
    r_stop = np.clip(np.ceil(yhi), 0, h_e).astype(np.int64)
    n_rows = np.maximum(r_stop - r_first, 0)
    e = np.repeat(np.arange(x0.size), n_rows)
    if e.size == 0:
        return np.zeros(total)
    row = r_first[e] + np.arange(e.size) - np.repeat(np.cumsum(n_rows) - n_rows, n_rows)
    ya = np.maximum(ylo[e], row)
    yb = np.minimum(yhi[e], row + 1.0)
    slope = (x1 - x0) / (y1 - y0)
    xlo_e, xhi_e = np.minimum(x0, x1)[e], np.maximum(x0, x1)[e]
    xa = np.clip(x0[e] + (ya - y0[e]) * slope[e], xlo_e, xhi_e)
    xb = np.clip(x0[e] + (yb - y0[e]) * slope[e], xlo_e, xhi_e)
    dy = (yb - ya) * np.sign(y1 - y0)[e] * wt[e]
    good = yb > ya
    row, xa, xb, dy, piece_win = row[good], xa[good], xb[good], dy[good], win[e][good]
    w = widths[piece_win]
    start_of_row = bases[piece_win] + row * (w + 1)  # the piece's row in the flat buffer

    # Per piece, G(j) = dy * int clamp(j + 1 - x(y), 0, 1) dy / dy is the coverage it adds
    # to column j; it is 0 left of the piece and dy right of it. Scatter G's differences.
    xmin, xmax = np.minimum(xa, xb), np.maximum(xa, xb)
    j_lo = np.clip(np.floor(xmin), 0, w).astype(np.int64)
    j_hi = np.clip(np.ceil(xmax), -1, w - 1).astype(np.int64)
    n_cols = np.maximum(j_hi - j_lo + 1, 0)
    p = np.repeat(np.arange(row.size), n_cols)
    first = np.cumsum(n_cols) - n_cols
    j = j_lo[p] + np.arange(p.size) - np.repeat(first, n_cols)
    a = j + 1.0
    dx = xb[p] - xa[p]
    flat = np.abs(dx) < _FLAT
    g_slanted = (_ramp_integral(a - xa[p]) - _ramp_integral(a - xb[p])) / np.where(flat, 1.0, dx)
    g_flat = np.clip(a - 0.5 * (xa[p] + xb[p]), 0.0, 1.0)
    g = dy[p] * np.where(flat, g_flat, g_slanted)
    diff = g.copy()
    diff[1:] -= g[:-1]
    has = n_cols > 0
    diff[first[has]] = g[first[has]]
    # Beyond the last listed column the piece adds its full dy.
    tail_col = np.where(has, j_hi + 1, j_lo)
    tail = dy.copy()
    tail[has] -= g[(first + n_cols - 1)[has]]

    idx = np.concatenate([start_of_row[p] + j, start_of_row + np.minimum(tail_col, w)])
    val = np.concatenate([diff, tail])
    return np.bincount(idx, weights=val, minlength=total)


def polygon_coverage(
    polygons: Sequence[FloatArray], weights: Sequence[float], shape: tuple[int, int]
) -> FloatArray:
    """Weighted exact area coverage of polygons on a ``shape`` pixel grid.

    Parameters
    ----------
    polygons : sequence of ndarray (n_i, 2)
        Simple polygons in image coordinates (pixel centres at integer coordinates).
    weights : sequence of float
        Value each polygon adds where it covers a pixel.
    shape : (int, int)
        ``(height, width)`` of the output.

    Returns
    -------
    ndarray (height, width) float64
        For every pixel, ``sum_k weights[k] * area(pixel ∩ polygons[k])``.

    Raises
    ------
    ValueError
        If ``polygons`` and ``weights`` differ in length.
    """
    return edge_coverage(*polygon_edges(polygons, weights), shape)
