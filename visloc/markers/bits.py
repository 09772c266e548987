"""Stages 9-10 of the marker pipeline: bit sampling through the homography and decoding.

Report Appendix G (Figure G.1.G): "direct sampling the interior of the perspective transformed
square, such that we obtain a set (matrix) of ones and zeros ... the set is compared with the
database in four orientations."

Each cell's mean grey level is sampled at a 3 x 3 grid in its central part, through the
homography of the four corners. The threshold is per marker: Otsu's split of the cell means
together with a ring of cells sampled in the white margin around the marker, so a marker whose
bits are mostly black still has a white class. All functions work on a batch of K candidates
at once (one OpenCV remap per frame).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from visloc.markers.dictionary import Dictionary

__all__ = ["CellSample", "decode", "otsu_threshold", "read_bits", "sample_cells", "square_to_quad"]

_SUB = np.array([0.3, 0.5, 0.7])  # sub-sample positions inside a cell, in cell units


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
    """

    cells: NDArray[np.float64]
    ring: NDArray[np.float64]


def square_to_quad(quads: NDArray) -> NDArray[np.float64]:
    """Homographies (K, 3, 3) mapping the unit square (0,0), (1,0), (1,1), (0,1) onto each of
    the quads (K, 4, 2), in closed form (Heckbert's projective mapping)."""
    q = np.asarray(quads, np.float64)
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


def _unit_grid(n: int) -> NDArray[np.float64]:
    """Sample points (9 (n^2 + 4n + 4), 2) in unit-square coordinates: 9 per cell for the n x n
    cells, then 9 per cell for the ring of cells around them."""
    ii, jj = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    cells = [np.stack([ii.ravel(), jj.ravel()], axis=1)]
    ring = [(-1, j) for j in range(-1, n + 1)] + [(n, j) for j in range(-1, n + 1)]
    ring += [(i, -1) for i in range(n)] + [(i, n) for i in range(n)]
    cells.append(np.array(ring))
    rc = np.concatenate(cells).astype(np.float64)
    sy, sx = np.meshgrid(_SUB, _SUB, indexing="ij")
    x = rc[:, 1:2] + sx.ravel()[None, :]  # column + sub-position
    y = rc[:, 0:1] + sy.ravel()[None, :]  # row + sub-position
    return np.stack([x.ravel(), y.ravel()], axis=1) / n


_GRIDS: dict[int, NDArray[np.float32]] = {}  # (3, S) sample points u, v, 1 per cell count


def sample_cells(gray: NDArray[np.uint8], quads: NDArray, n: int) -> CellSample:
    """Mean grey level of each of the ``n x n`` cells of each quad and of the ring around it.

    Parameters
    ----------
    gray : ndarray (H, W) uint8
    quads : ndarray (K, 4, 2) or (4, 2)
        Corners clockwise in the image; corner 0 is the grid's top-left. The corners are the
        outer corners of the cell area (pixel-centre convention: a pixel's area is
        ``[x - 0.5, x + 0.5]``).
    n : int
        Cells per side including the black border (bits per side + 2).
    """
    q = np.asarray(quads, np.float64).reshape(-1, 4, 2)
    if len(q) == 0:
        return CellSample(np.zeros((0, n, n)), np.zeros((0, 4 * n + 4)))
    if n not in _GRIDS:
        uv = _unit_grid(n)
        _GRIDS[n] = np.vstack([uv.T, np.ones(len(uv))]).astype(np.float32)
    uv1 = _GRIDS[n]  # (3, S): u, v, 1
    hom = (square_to_quad(q).reshape(-1, 3).astype(np.float32) @ uv1).reshape(len(q), 3, -1)  # (K, 3, S)
    mx, my = hom[:, 0] / hom[:, 2], hom[:, 1] / hom[:, 2]
    vals = cv2.remap(gray, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    vals = vals.reshape(len(q), -1, 9).sum(axis=2, dtype=np.float64) / 9.0
    return CellSample(vals[:, : n * n].reshape(-1, n, n), vals[:, n * n :])


def otsu_threshold(values: NDArray) -> tuple[NDArray, NDArray, NDArray]:
    """Otsu's two-class split of each row of ``values`` (K, m).

    Returns ``(threshold, dark_mean, bright_mean)``, each (K,).
    """
    v = np.sort(np.atleast_2d(np.asarray(values, np.float64)), axis=1)
    m = v.shape[1]
    c = np.cumsum(v, axis=1)
    k = np.arange(1, m)
    m0 = c[:, :-1] / k
    m1 = (c[:, -1:] - c[:, :-1]) / (m - k)
    between = k * (m - k) * (m1 - m0) ** 2
    i = np.argmax(between, axis=1)
    r = np.arange(len(v))
    dark, bright = m0[r, i], m1[r, i]
    return 0.5 * (dark + bright), dark, bright


def read_bits(
    sample: CellSample, border_error_rate: float = 0.35, min_contrast: float = 10.0
) -> tuple[NDArray[np.bool_], NDArray[np.uint8], NDArray, NDArray]:
    """Threshold the cells into bits and check the black border.

    Returns
    -------
    valid : ndarray (K,) bool
        Contrast at least ``min_contrast`` and at most ``border_error_rate * (n-2)^2`` white
        border cells (OpenCV's rule).
    bits : ndarray (K, n-2, n-2) uint8
        Inner cells, 1 = white.
    margin : ndarray (K,)
        Smallest distance of an inner cell from the threshold over half the contrast, in [0, 1].
    contrast : ndarray (K,)
        Bright class mean minus dark class mean, grey levels.
    """
    cells = sample.cells
    k, n, _ = cells.shape
    thr, dark, bright = otsu_threshold(np.concatenate([cells.reshape(k, -1), sample.ring], axis=1))
    contrast = bright - dark
    white = cells > thr[:, None, None]
    border = np.ones((n, n), bool)
    border[1:-1, 1:-1] = False
    border_white = white[:, border].sum(axis=1)
    valid = (contrast >= min_contrast) & (border_white <= int(border_error_rate * (n - 2) ** 2))
    inner = cells[:, 1:-1, 1:-1]
    margin = np.abs(inner - thr[:, None, None]).reshape(k, -1).min(axis=1) / np.maximum(0.5 * contrast, 1e-6)
    return valid, white[:, 1:-1, 1:-1].astype(np.uint8), np.minimum(margin, 1.0), contrast


def decode(
    bits: NDArray[np.uint8], dictionary: Dictionary, error_correction_rate: float = 0.6
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.intp], NDArray[np.bool_]]:
    """Stage 10: match bit grids (K, s, s) against ``dictionary`` in four orientations.

    At most ``int(dictionary.max_correction * error_correction_rate)`` bits are corrected
    (OpenCV's rule).

    Returns
    -------
    ids, corner_shift, hamming, ok : ndarray (K,)
        ``corner_shift`` is the index of the candidate corner that is the marker's own
        top-left; ``ok`` is False where no marker is close enough.
    """
    b = np.asarray(bits).reshape(len(bits), -1).astype(np.uint64)
    if b.shape[1] != dictionary.marker_size**2:
        raise ValueError(f"bits must be (K, {dictionary.marker_size}, {dictionary.marker_size}), got {np.shape(bits)}")
    weights = np.left_shift(np.uint64(1), np.arange(b.shape[1], dtype=np.uint64))
    codes = (b * weights).sum(axis=1, dtype=np.uint64)
    dist = np.bitwise_count(codes[:, None, None] ^ dictionary.codes[None])  # (K, n_ids, 4)
    flat = dist.reshape(len(b), -1).argmin(axis=1)
    ids, r = np.divmod(flat, 4)
    hamming = dist.reshape(len(b), -1)[np.arange(len(b)), flat].astype(np.intp)
    ok = hamming <= int(dictionary.max_correction * error_correction_rate)
    # observed = rot90(true, r) (counter-clockwise quarter turns): the true top-left cell
    # is then at candidate corner 0, 3, 2, 1 for r = 0, 1, 2, 3.
    return ids.astype(np.intp), ((4 - r) % 4).astype(np.intp), hamming, ok
