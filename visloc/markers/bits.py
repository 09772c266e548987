"""Stages 9-10 of the marker pipeline: bit sampling through the homography and decoding.

Report Appendix G (Figure G.1.G): "direct sampling the interior of the perspective transformed
square, such that we obtain a set (matrix) of ones and zeros ... the set is compared with the
database in four orientations."

Each cell is sampled at a small grid of points in its central part (3 x 3 for the cheap first
look, 4 x 4 spread over the inner 60 % of the cell for the final read), through the
homography of the four corners. The threshold is per marker: Otsu's split of the cell means
together with a ring of cells sampled in the white margin around the marker, so a marker whose
bits are mostly black still has a white class. A cell's bit is the majority of its samples
(the fraction of white samples, as OpenCV counts the white pixels of each cell), so a stain,
a reflection or a printing flaw over part of a cell does not flip it. All functions work on a
batch of K candidates at once (one OpenCV remap per call). Compiled code
(``visloc.markers._cells``, built with the package) computes the remap's maps (the numpy
version's single-precision operations: the same maps) and reads the sampled cells into bits
(:func:`read_cells`), with :func:`read_bits` as the fallback: the same operations in the same
order, the same bits.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import NamedTuple

import cv2
import numpy as np
from numpy.typing import NDArray

from visloc._checks import check_int
from visloc._compiled import use_compiled
from visloc.markers.dictionary import Dictionary, _check_binary

try:
    from visloc.markers import _cells
except ImportError:  # installed without a C compiler: the numpy versions
    _cells = None

#: Whether :func:`read_cells` runs compiled code.
NATIVE_CELLS = _cells is not None

__all__ = ["NATIVE_CELLS", "BitRead", "CellSample", "cell_white_fractions", "decode", "otsu_threshold", "read_bits",
           "read_cells", "sample_cells", "square_to_quad"]


@dataclass(frozen=True, eq=False)
class CellSample:
    """Grey levels of K candidates' cells.

    Attributes
    ----------
    cells : ndarray (K, n, n) float
        Mean grey level of each cell of the marker incl. its border (n = bits + 2); row 0
        runs from corner 0 to corner 1, column 0 from corner 0 to corner 3.
    ring : ndarray (K, 4n + 4) float
        Mean grey level of the cells of the ring just outside the border (the white margin).
    samples : ndarray (K, n, n, S) uint8 or None
        The S grey levels sampled inside each cell (their mean is ``cells``).
    """

    cells: NDArray[np.float64]
    ring: NDArray[np.float64]
    samples: NDArray[np.uint8] | None = None


def square_to_quad(quads: NDArray) -> NDArray[np.float64]:
    """Homographies mapping the unit square onto quads, in closed form (Heckbert's projective
    mapping).

    Parameters
    ----------
    quads : ndarray (K, 4, 2) or (4, 2)
        Corners ``(x, y)`` of each quad, px; corner ``i`` is the image of the unit square's
        corner ``(0, 0), (1, 0), (1, 1), (0, 1)`` in turn.

    Returns
    -------
    ndarray (K, 3, 3) or (3, 3) float64
        ``H`` per quad with ``[x w, y w, w] = H @ [u, v, 1]``, ``H[2, 2] = 1``: unit-square
        point ``(u, v)`` lands on image point ``(x, y)``, in the pixel convention of ``quads``.

    Raises
    ------
    ValueError
        If ``quads`` is not (K, 4, 2) or (4, 2).
    """
    q = np.asarray(quads, np.float64)
    if q.shape[-2:] != (4, 2) or q.ndim not in (2, 3):
        raise ValueError(f"quads must be (K, 4, 2) or (4, 2), got shape {q.shape}")
    if q.ndim == 2:
        return square_to_quad(q[None])[0]
    x0, x1, x2, x3 = (q[:, i, 0] for i in range(4))
    y0, y1, y2, y3 = (q[:, i, 1] for i in range(4))
    dx1, dx2, dx3 = x1 - x2, x3 - x2, x0 - x1 + x2 - x3
    dy1, dy2, dy3 = y1 - y2, y3 - y2, y0 - y1 + y2 - y3
    den = dx1 * dy2 - dx2 * dy1
    den = np.where(np.abs(den) < 1e-12, 1e-12, den)
    g = (dx3 * dy2 - dx2 * dy3) / den
    h = (dx1 * dy3 - dx3 * dy1) / den
    H = np.empty((len(q), 3, 3))
    H[:, 0, 0] = x1 - x0 + g * x1
    H[:, 0, 1] = x3 - x0 + h * x3
    H[:, 0, 2] = x0
    H[:, 1, 0] = y1 - y0 + g * y1
    H[:, 1, 1] = y3 - y0 + h * y3
    H[:, 1, 2] = y0
    H[:, 2, 0] = g
    H[:, 2, 1] = h
    H[:, 2, 2] = 1.0
    return H


def _sub_positions(per_side: int) -> NDArray[np.float64]:
    """Sample positions across a cell, in cell units: 0.2 apart around its centre (0.3, 0.5,
    0.7 for 3; 0.2 ... 0.8 for 4)."""
    return 0.5 + 0.2 * (np.arange(per_side) - 0.5 * (per_side - 1))


def _unit_grid(n: int, per_side: int) -> NDArray[np.float64]:
    """Sample points (S (n^2 + 4n + 4), 2) in unit-square coordinates, S = per_side^2 per cell:
    the n x n cells, then the ring of cells around them."""
    ii, jj = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    cells = [np.stack([ii.ravel(), jj.ravel()], axis=1)]
    ring = [(-1, j) for j in range(-1, n + 1)] + [(n, j) for j in range(-1, n + 1)]
    ring += [(i, -1) for i in range(n)] + [(i, n) for i in range(n)]
    cells.append(np.array(ring))
    rc = np.concatenate(cells).astype(np.float64)
    sub = _sub_positions(per_side)
    sy, sx = np.meshgrid(sub, sub, indexing="ij")
    x = rc[:, 1:2] + sx.ravel()[None, :]  # column + sub-position
    y = rc[:, 0:1] + sy.ravel()[None, :]  # row + sub-position
    return np.stack([x.ravel(), y.ravel()], axis=1) / n


def _map_points(quads: NDArray, uv1: NDArray[np.float32]) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Image x and y (K, P) of the unit-square points ``uv1`` (3, P: u, v, 1) on each quad (K, 4, 2),
    through :func:`square_to_quad` in single precision (``cv2.remap``'s maps), each coordinate
    ``(h0 u + h1 v) + h2`` over ``(h6 u + h7 v) + h8``, as ``_cells.quad_maps`` computes them."""
    H = square_to_quad(quads).astype(np.float32)[:, :, :, None]  # (K, 3, 3, 1)
    hom = H[:, :, 0] * uv1[0] + H[:, :, 1] * uv1[1] + H[:, :, 2]  # (K, 3, P)
    return hom[:, 0] / hom[:, 2], hom[:, 1] / hom[:, 2]


def _read_points(gray: NDArray[np.uint8], quads: NDArray, uv1: NDArray[np.float32],
                 native: bool | None) -> NDArray[np.uint8]:
    """Grey levels (K, P) at the unit-square points ``uv1`` (3, P) of each quad (K, 4, 2),
    read by ``cv2.remap`` (bilinear, the image's edge pixels repeated beyond it) through the
    maps of :func:`_map_points`, computed by compiled code (``_cells.quad_maps``, the same
    maps) unless ``native`` is False or it was not built."""
    k, n_points = len(quads), uv1.shape[1]
    if use_compiled(native, _cells, "visloc.markers._cells"):
        mx, my = (np.frombuffer(a, np.float32).reshape(k, n_points) for a in _cells.quad_maps(
            np.ascontiguousarray(quads, np.float64), k, np.ascontiguousarray(uv1[:2]), n_points))
    else:
        mx, my = _map_points(quads, uv1)
    step = 32000  # OpenCV's maps stay under 32767 px a side
    if k <= step and n_points <= step:
        return cv2.remap(gray, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return np.vstack([np.hstack([cv2.remap(gray, mx[r : r + step, c : c + step], my[r : r + step, c : c + step],
                                           cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
                                 for c in range(0, n_points, step)]) for r in range(0, k, step)])


def _checked_quads(gray: NDArray[np.uint8], quads: NDArray, n: int, per_side: int) -> NDArray[np.float64]:
    """``quads`` as (K, 4, 2) float64, having checked the arguments of :func:`sample_cells` and
    :func:`cell_white_fractions` (scalar checks and one vectorised look at the corners)."""
    if not isinstance(gray, np.ndarray) or gray.dtype != np.uint8:
        raise TypeError(f"gray must be a uint8 array, got {getattr(gray, 'dtype', type(gray).__name__)}")
    if gray.ndim != 2 or not gray.size:
        raise ValueError(f"gray must be a non-empty (H, W) image, got shape {gray.shape}")
    if type(n) is not int or type(per_side) is not int or n < 1 or per_side < 1:  # else plainly valid
        check_int(n, "n", low=1)
        check_int(per_side, "per_side", low=1)
    q = np.asarray(quads, np.float64)
    if q.shape[-2:] != (4, 2) or q.ndim not in (2, 3):
        raise ValueError(f"quads must be (K, 4, 2) or (4, 2), got shape {q.shape}")
    if not np.isfinite(q).all():
        raise ValueError("quads: every corner must be finite")
    return q[None] if q.ndim == 2 else q


def _check_border(border: int, n: int) -> None:
    """Raise unless a black border of ``border`` cells leaves bits inside ``n`` cells a side."""
    check_int(border, "border", low=1)
    if n <= 2 * border:
        raise ValueError(f"n must be more than 2 border ({2 * border}), got {n}")


_GRIDS: dict[tuple[int, int], NDArray[np.float32]] = {}  # (3, P) points u, v, 1 per (n, per_side)


def sample_cells(gray: NDArray[np.uint8], quads: NDArray, n: int, *, per_side: int = 3,
                 native: bool | None = None) -> CellSample:
    """Grey levels of each of the ``n x n`` cells of each quad and of the ring around it.

    Parameters
    ----------
    gray : ndarray (H, W) uint8
        Grey image, not empty.
    quads : ndarray (K, 4, 2) or (4, 2)
        Corners ``(x, y)``, px, clockwise in the image; corner 0 is the grid's top-left. The
        corners are the outer corners of the cell area (pixel centres at integer
        coordinates: a pixel's area is ``[x - 0.5, x + 0.5]``). They must be finite.
    n : int
        Cells per side including the black border (bits per side + 2 x border cells), >= 1.
    per_side : int
        Samples across each cell (>= 1; ``per_side ** 2`` per cell, 0.2 cell apart), read as
        ``cv2.remap`` reads them (bilinear, the image's edge pixels repeated beyond it).
    native : bool or None
        Compute the sampling maps with compiled code (``True``: ``visloc.markers._cells``,
        the same maps) or with numpy (``False``); ``None``: compiled when it was built.

    Returns
    -------
    CellSample
        ``cells`` (K, n, n) and ``ring`` (K, 4n + 4) mean grey levels, ``samples``
        (K, n, n, per_side ** 2) uint8; row 0 of the cells runs from corner 0 to corner 1.

    Raises
    ------
    TypeError
        If ``gray`` is not a uint8 array, or ``n`` or ``per_side`` is not an integer.
    ValueError
        If ``gray`` is empty or not (H, W), ``quads`` is not (K, 4, 2) or (4, 2), a corner is
        not finite, or ``n`` or ``per_side`` is < 1.
    """
    q = _checked_quads(gray, quads, n, per_side)
    m = per_side * per_side
    if len(q) == 0:
        return CellSample(np.zeros((0, n, n)), np.zeros((0, 4 * n + 4)), np.zeros((0, n, n, m), np.uint8))
    if (n, per_side) not in _GRIDS:
        uv = _unit_grid(n, per_side)
        _GRIDS[n, per_side] = np.vstack([uv.T, np.ones(len(uv))]).astype(np.float32)
    uv1 = _GRIDS[n, per_side]  # (3, P): u, v, 1
    raw = _read_points(gray, q, uv1, native).reshape(len(q), -1, m)
    if use_compiled(native, _cells, "visloc.markers._cells"):
        vals = np.frombuffer(_cells.sample_means(raw, len(q), raw.shape[1], m), np.float64).reshape(len(q), -1)
    else:
        vals = raw.sum(axis=2, dtype=np.uint32) / m  # whole sums: float64's, in two thirds of the time
    samples = raw[:, : n * n].reshape(len(q), n, n, m)
    return CellSample(vals[:, : n * n].reshape(-1, n, n), vals[:, n * n :], samples)


def read_cells(gray: NDArray[np.uint8], quads: NDArray, n: int, *, per_side: int = 3, border_error_rate: float = 0.35,
               min_contrast: float = 10.0, border: int = 1, min_quiet_zone: float = 0.0,
               native: bool | None = None) -> tuple[CellSample, BitRead]:
    """:func:`sample_cells` then :func:`read_bits` (one threshold per marker): the detector's
    stage 9. The read is compiled (``visloc.markers._cells``: Otsu's threshold, the majority
    read and the border checks for each candidate in one pass, the numpy version's operations
    in its order: the same bits).

    Parameters
    ----------
    gray, quads : as :func:`sample_cells`
    n : int
        Cells per side including the black border (bits per side + 2 ``border``), > 2 ``border``.
    per_side : int
        Samples across each cell (:func:`sample_cells`).
    border_error_rate : float
        Tolerated white border cells as a fraction of the bit count (:func:`read_bits`).
    min_contrast : float
        Least difference between the white and black class means, grey levels.
    border : int
        Width of the black border in cells, >= 1.
    min_quiet_zone : float
        Least fraction of the ring cells that must be white (:func:`read_bits`).
    native : bool or None
        Run the compiled sampling and read (``True``) or the numpy ones (``False``); ``None``:
        the compiled ones when they were built (:data:`NATIVE_CELLS`).

    Returns
    -------
    sample : CellSample
        The sampled cells (:func:`sample_cells`).
    read : BitRead
        The bits and checks (:func:`read_bits`), bits (K, n - 2 border, n - 2 border).

    Raises
    ------
    TypeError
        As :func:`sample_cells`, or if ``border`` is not an integer.
    ValueError
        As :func:`sample_cells`, or if ``border`` is < 1 or ``n`` is not more than 2 ``border``.
    RuntimeError
        If ``native=True`` and the compiled module was not built.
    """
    sample = sample_cells(gray, quads, n, per_side=per_side, native=native)
    k = len(sample.cells)
    if k == 0 or not use_compiled(native, _cells, "visloc.markers._cells"):
        return sample, read_bits(sample, border_error_rate=border_error_rate, min_contrast=min_contrast,
                                 border=border, min_quiet_zone=min_quiet_zone)  # (checks border)
    _check_border(border, n)
    s = n - 2 * border
    valid, bits, scal = _cells.read_samples(np.ascontiguousarray(sample.samples), np.ascontiguousarray(sample.ring),
                                            k, n, per_side * per_side, border, float(border_error_rate),
                                            float(min_contrast), float(min_quiet_zone))
    margin, contrast, thr = np.frombuffer(scal, np.float64).reshape(3, k)
    return sample, BitRead(np.frombuffer(valid, np.bool_), np.frombuffer(bits, np.uint8).reshape(k, s, s), margin,
                           contrast, thr)


@lru_cache(maxsize=64)
def _area_grid(n: int, per_side: int, margin: float) -> NDArray[np.float32]:
    """(3, (n per_side)^2) points u, v, 1 of :func:`cell_white_fractions` in the unit square,
    row by row (read-only)."""
    sub = margin + (1 - 2 * margin) * (np.arange(per_side) + 0.5) / per_side
    cells = (np.arange(n)[:, None] + sub[None, :]).ravel() / n  # positions along one side
    u = np.broadcast_to(cells[None, :], (len(cells), len(cells)))
    grid = np.stack([u.ravel(), u.T.ravel(), np.ones(u.size)]).astype(np.float32)
    grid.setflags(write=False)
    return grid


def cell_white_fractions(gray: NDArray[np.uint8], quads: NDArray, n: int, threshold: NDArray, *,
                         per_side: int = 8, margin: float = 0.13, native: bool | None = None) -> NDArray[np.float64]:
    """Fraction of each cell's read area brighter than the marker's threshold, as OpenCV
    reads cells (the share of white pixels of each cell of the marker warped square, a
    ``margin`` of the cell left out on every side).

    Parameters
    ----------
    gray, quads : as :func:`sample_cells`
    n : int
        Cells per side including the border, >= 1.
    threshold : ndarray (K,)
        Each marker's grey-level threshold, one per quad.
    per_side : int
        Samples across a cell's read area (>= 1; ``per_side ** 2`` per cell, evenly spread).
    margin : float
        Fraction of the cell left out on each side, in [0, 0.5) (OpenCV's
        ``perspectiveRemoveIgnoredMarginPerCell``, 0.13).
    native : bool or None
        As for :func:`sample_cells`.

    Returns
    -------
    ndarray (K, n, n) float64
        Fraction in [0, 1] of each cell's samples brighter than its marker's threshold; row
        0 runs from corner 0 to corner 1, column 0 from corner 0 to corner 3.

    Raises
    ------
    TypeError
        As :func:`sample_cells`.
    ValueError
        As :func:`sample_cells`, or if ``threshold`` does not hold one value per quad.
    """
    q = _checked_quads(gray, quads, n, per_side)
    t = np.asarray(threshold, np.float64)
    if t.size != len(q):
        raise ValueError(f"threshold must hold one value per quad ({len(q)}), got shape {t.shape}")
    if len(q) == 0:
        return np.zeros((0, n, n))
    uv1 = _area_grid(n, per_side, float(margin))
    side = n * per_side
    vals = _read_points(gray, q, uv1, native)
    if use_compiled(native, _cells, "visloc.markers._cells"):
        return np.frombuffer(_cells.white_fractions(vals, np.ascontiguousarray(t.reshape(-1), np.float64), len(q), n,
                                                    per_side), np.float64).reshape(len(q), n, n)
    white = vals > t.reshape(-1, 1)
    # the count of each cell's samples, one axis at a time (a third of mean(axis=(2, 4))'s time)
    count = white.view(np.uint8).reshape(len(q), n, per_side, side).sum(axis=2, dtype=np.uint32)
    return count.reshape(len(q), n, n, per_side).sum(axis=3) / (per_side * per_side)


def otsu_threshold(values: NDArray) -> tuple[NDArray, NDArray, NDArray]:
    """Otsu's two-class split of each row of ``values``.

    Parameters
    ----------
    values : ndarray (K, m) or (m,)
        Grey levels, one set of m >= 2 values per row.

    Returns
    -------
    threshold, dark_mean, bright_mean : ndarray (K,) float64
        The two classes' mean grey levels at the split that maximises the between-class
        variance, and the threshold midway between them.

    Raises
    ------
    ValueError
        If ``values`` is not (K, m) or (m,) with m >= 2, or holds NaN or infinite values (or
        a row whose sum overflows float64).
    """
    v = np.asarray(values, np.float64)
    if v.ndim not in (1, 2) or v.shape[-1] < 2:
        raise ValueError(f"values must be (K, m) or (m,) with m >= 2, got shape {v.shape}")
    v = np.sort(np.atleast_2d(v), axis=1)
    m = v.shape[1]
    c = np.cumsum(v, axis=1)
    if not np.isfinite(c[:, -1]).all():  # a row's sum: NaN or infinite with any of its values
        raise ValueError("values must be finite (and sum to less than float64's largest value)")
    k = np.arange(1, m)
    m0 = c[:, :-1] / k
    m1 = (c[:, -1:] - c[:, :-1]) / (m - k)
    between = k * (m - k) * (m1 - m0) ** 2
    i = np.argmax(between, axis=1)
    r = np.arange(len(v))
    dark, bright = m0[r, i], m1[r, i]
    return 0.5 * (dark + bright), dark, bright


class BitRead(NamedTuple):
    """What :func:`read_bits` read from K candidates.

    Attributes
    ----------
    valid : ndarray (K,) bool
        Contrast at least ``min_contrast``, at most ``border_error_rate * bits^2`` white
        border cells (OpenCV's rule) and at least ``min_quiet_zone`` of the ring cells white.
    bits : ndarray (K, s, s) uint8
        Inner cells, 1 = white.
    margin : ndarray (K,)
        Smallest distance of an inner cell's mean from the threshold over half the contrast,
        in [0, 1].
    contrast : ndarray (K,)
        Bright class mean minus dark class mean, grey levels.
    threshold : ndarray (K,)
        Each candidate's grey-level threshold (Otsu's split of its cells and ring).
    """

    valid: NDArray[np.bool_]
    bits: NDArray[np.uint8]
    margin: NDArray
    contrast: NDArray
    threshold: NDArray


def read_bits(
    sample: CellSample, *, border_error_rate: float = 0.35, min_contrast: float = 10.0, border: int = 1,
    min_quiet_zone: float = 0.0, shading: bool = False,
) -> BitRead:
    """Threshold the cells into bits and check the black border.

    A cell is white when most of its samples are above the marker's threshold (its mean
    decides a tie; without samples, its mean alone).

    Parameters
    ----------
    sample : CellSample
        Cells (K, n, n), ring (K, 4n + 4) and, optionally, samples (K, n, n, S) of K
        candidates (:func:`sample_cells`).
    border_error_rate : float
        Tolerated white border cells as a fraction of the bit count.
    min_contrast : float
        Least difference between the white and black class means, grey levels.
    border : int
        Width of the black border in cells (OpenCV's ``markerBorderBits``), >= 1 and less than
        half the cells a side.
    min_quiet_zone : float
        Least fraction of the ring cells just outside the border that must be white: a
        printed marker sits in a white quiet zone, a dark patch with bright specks in it
        (a star field, a pattern in shadow) does not.
    shading : bool
        Threshold each cell at a plane fitted to the grey levels of all cells and of the ring
        (the marker's local mean level) instead of at one level: for light that changes across
        the marker (glare, a shadow's edge, vignetting), where one threshold reads the cells
        of the dim side as black.

    Returns
    -------
    BitRead
        ``valid`` (K,) bool, ``bits`` (K, n - 2 border, n - 2 border) uint8 (1 = white),
        ``margin`` (K,) in [0, 1], ``contrast`` (K,) and ``threshold`` (K,) in grey levels.

    Raises
    ------
    TypeError
        If ``border`` is not an integer.
    ValueError
        If ``border`` is < 1 or leaves no cell inside it (n <= 2 ``border``), or the cells
        (:func:`otsu_threshold`) are not finite.
    """
    cells = sample.cells
    k, n, _ = cells.shape
    _check_border(border, n)
    if k == 0:  # no candidates: no reads (reshape(0, -1) cannot size an empty batch)
        s = n - 2 * border
        empty = np.zeros(0)
        return BitRead(np.zeros(0, bool), np.zeros((0, s, s), np.uint8), empty, empty.copy(), empty.copy())
    values = np.concatenate([cells.reshape(k, -1), sample.ring], axis=1)
    thr, dark, bright = otsu_threshold(values)
    contrast = bright - dark
    t = thr[:, None, None]
    if shading:  # a plane through every cell's and ring cell's mean: the local mid level
        xy = _cell_centres(n)
        fit = np.linalg.lstsq(np.c_[np.ones(len(xy)), xy], values.T, rcond=None)[0]  # (3, K)
        t = (fit[0][:, None] + fit[1][:, None] * xy[: n * n, 0] + fit[2][:, None] * xy[: n * n, 1]).reshape(k, n, n)
    if sample.samples is not None and sample.samples.shape[-1] > 1:
        m = sample.samples.shape[-1]
        # whole grey levels: v > t exactly when v > floor(t), compared in integers
        above = np.count_nonzero(sample.samples > np.floor(t).astype(np.int16)[..., None], axis=-1)
        white = np.where(2 * above == m, cells > t, 2 * above > m)
    else:
        white = cells > t
    frame = np.ones((n, n), bool)
    frame[border:-border, border:-border] = False
    border_white = white[:, frame].sum(axis=1)
    size = n - 2 * border
    valid = (contrast >= min_contrast) & (border_white <= int(border_error_rate * size**2))
    if min_quiet_zone > 0:
        valid &= (sample.ring > thr[:, None]).mean(axis=1) >= min_quiet_zone
    inner = (slice(None), slice(border, -border), slice(border, -border))
    margin = np.abs(cells[inner] - t[inner] if shading else cells[inner] - t).reshape(k, -1).min(axis=1)
    margin = margin / np.maximum(0.5 * contrast, 1e-6)
    return BitRead(valid, white[inner].astype(np.uint8), np.minimum(margin, 1.0), contrast, thr)


@lru_cache(maxsize=16)
def _cell_centres(n: int) -> NDArray[np.float64]:
    """(x, y) of the centres (n^2 + 4n + 4, 2), in cells, of the n x n cells then of the ring
    around them, in :func:`sample_cells`' order."""
    ii, jj = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    ring = [(-1, j) for j in range(-1, n + 1)] + [(n, j) for j in range(-1, n + 1)]
    ring += [(i, -1) for i in range(n)] + [(i, n) for i in range(n)]
    rc = np.concatenate([np.stack([ii.ravel(), jj.ravel()], axis=1), np.array(ring)]).astype(np.float64)
    out = rc[:, ::-1] + 0.5
    out.setflags(write=False)
    return out


def decode(
    bits: NDArray[np.uint8], dictionary: Dictionary, *, error_correction_rate: float = 0.6,
    native: bool | None = None,
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.intp], NDArray[np.bool_]]:
    """Stage 10: match bit grids against ``dictionary`` in four orientations.

    Parameters
    ----------
    bits : ndarray (K, s, s) uint8 or bool
        Inner cells read from K candidates (K may be 0), 0/1 (1 = white), row 0 running from
        candidate corner 0 to corner 1 (:func:`read_bits`); ``s`` is ``dictionary.marker_size``.
    dictionary : Dictionary
        The markers to match.
    error_correction_rate : float
        At most ``int(dictionary.max_correction * error_correction_rate)`` bits are corrected
        (OpenCV's rule).
    native : bool or None
        Match uint8 or bool bits with compiled code (``True``: ``visloc.markers._cells``, the
        same matches; other types always with numpy) or with numpy (``False``); ``None``:
        compiled when it was built.

    Returns
    -------
    ids, corner_shift, hamming, ok : ndarray (K,)
        intp, intp, intp and bool: the closest marker's id, the index (0-3) of the candidate
        corner that is the marker's own top-left, the number of differing bits, and
        whether the marker is close enough (False: no marker matched).

    Raises
    ------
    ValueError
        If ``bits`` does not hold ``s * s`` cells per candidate or holds values other than 0
        and 1.
    RuntimeError
        If ``native=True`` and the compiled module was not built.
    """
    b = np.asarray(bits)
    s2 = dictionary.marker_size**2
    if b.ndim == 0 or math.prod(b.shape[1:]) != s2:
        raise ValueError(f"bits must be (K, {dictionary.marker_size}, {dictionary.marker_size}), got {b.shape}")
    k = len(b)
    max_bits = int(dictionary.max_correction * error_correction_rate)
    if use_compiled(native, _cells, "visloc.markers._cells") and k and b.dtype in (np.uint8, np.bool_):
        out, ok = np.empty((3, k), np.intp), np.empty(k, np.bool_)
        if _cells.match_codes(np.ascontiguousarray(b).view(np.uint8), k,
                              np.ascontiguousarray(dictionary.codes, np.uint64), max_bits, out, ok):
            return out[0], out[1], out[2], ok  # (False: a value other than 0 and 1, raised below)
    _check_binary(b, "bits")
    b = b.reshape(k, s2).astype(np.uint64)
    weights = np.left_shift(np.uint64(1), np.arange(s2, dtype=np.uint64))
    codes = (b * weights).sum(axis=1, dtype=np.uint64)
    dist = np.bitwise_count(codes[:, None] ^ dictionary.codes.reshape(1, -1))  # (K, 4 n_ids): id, then rotation
    flat = dist.argmin(axis=1)
    ids, r = np.divmod(flat, 4)
    hamming = dist[np.arange(k), flat].astype(np.intp)
    ok = hamming <= max_bits
    # observed = rot90(true, r) (counter-clockwise quarter turns): the true top-left cell
    # is then at candidate corner 0, 3, 2, 1 for r = 0, 1, 2, 3.
    return ids.astype(np.intp), ((4 - r) % 4).astype(np.intp), hamming, ok
