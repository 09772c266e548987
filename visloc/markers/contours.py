"""Stages 4-5 of the marker pipeline: contour following and candidate filtering.

Report Appendix G: "From the binary image all the contours are determined ... Then all closed
contours are determined using a line following method" (Figure G.1.C). Only *outer* borders of
ink regions are kept, so the inner border of a marker's black frame never becomes a second
candidate, and only those of regions that enclose a hole: a marker's frame encloses its cells.

:func:`outer_borders` is OpenCV's border follower (Suzuki-Abe) and gives every border, for
the pictures of ``--explain``. The detector asks only for the borders it can use
(:func:`enclosing_borders`). Compiled code (``visloc.markers._borders``, built with the
package) finds them without following the thousands of texture borders around them: it labels
the ink runs of each row, tells the regions with a hole by their Euler number (runs and
touching pairs of runs), and follows only those regions' outer borders, as Suzuki-Abe (and
OpenCV) do. It returns them packed instead of one Python array per border; on textured frames
most of ``cv2.findContours``'s time goes into such arrays for borders that are thrown away.
Without the compiled module ``cv2.findContours`` is used; both give the same borders, point for
point. The candidate filter is compiled too (``visloc.markers._filter``: the same tests, with
Douglas-Peucker as ``cv2.approxPolyDP`` computes it), with the OpenCV calls as the fallback.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import pairwise

import cv2
import numpy as np
from numpy.typing import NDArray

from visloc._compiled import use_compiled

_NEXT = np.array([1, 2, 3, 0])

try:
    from visloc.markers import _borders
except ImportError:  # the package was installed without a C compiler: OpenCV's follower
    _borders = None
try:
    from visloc.markers import _filter
except ImportError:  # (each module on its own: one that failed to build leaves the others)
    _filter = None

#: Whether :func:`enclosing_borders` and :func:`filter_candidates` run compiled code.
NATIVE_BORDERS = _borders is not None and _filter is not None

__all__ = ["NATIVE_BORDERS", "CandidateFilter", "enclosing_borders", "filter_candidates", "find_candidates",
           "find_contours", "outer_borders", "perimeter_bounds"]


def outer_borders(binary: NDArray[np.uint8]) -> tuple[list[NDArray[np.int32]], NDArray[np.bool_]]:
    """Stage 4: outer borders of the ink (255) regions of a binary image, and which of them
    enclose at least one hole.

    Parameters
    ----------
    binary : ndarray (H, W) uint8
        Binary image, ink 255 (any non-zero value), background 0
        (:func:`~visloc.markers.binarize.threshold`).

    Returns
    -------
    contours : list of ndarray (N, 1, 2) int32
        One per outer border, in OpenCV's layout: the ``(x, y)`` pixel centres (integer
        coordinates) of a closed 8-connected border, traced in order. Holes (inner borders)
        are left out.
    encloses : ndarray (len(contours),) bool
        Whether each border's region encloses at least one hole.

    Raises
    ------
    ValueError
        If ``binary`` is not a (H, W) uint8 image.
    """
    _check_binary(binary)
    contours, hierarchy = cv2.findContours(binary, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
    if hierarchy is None:
        return [], np.zeros(0, bool)
    h = hierarchy[0]
    outer = np.flatnonzero(h[:, 3] < 0)  # no parent: an outer border (RETR_CCOMP: holes are the children)
    return [contours[i] for i in outer], h[outer, 2] >= 0  # a child: it encloses a hole


def enclosing_borders(binary: NDArray[np.uint8], *, min_len: int = 1, max_len: int | None = None,
                      native: bool | None = None) -> list[NDArray[np.int32]]:
    """Stage 4 as the detector runs it: the outer borders of the ink regions that enclose at
    least one hole, with ``min_len <= points <= max_len``.

    The same borders, in the same order and point for point, as ``outer_borders(binary)``
    filtered by its hole flags.

    Parameters
    ----------
    binary : ndarray (H, W) uint8
        Binary image, ink 255 (any non-zero value), background 0
        (:func:`~visloc.markers.binarize.threshold`).
    min_len : int
        Fewest points a kept border may have (e.g. from :func:`perimeter_bounds`).
    max_len : int or None
        Most points a kept border may have; ``None``: no upper bound.
    native : bool or None
        The compiled follower (``True``) or ``cv2.findContours`` (``False``); ``None`` uses
        the compiled one when it was built (:data:`NATIVE_BORDERS`).

    Returns
    -------
    list of ndarray (N, 2) int32
        Each kept border's ``(x, y)`` pixel centres (integer coordinates), traced in order.

    Raises
    ------
    ValueError
        If ``binary`` is not a (H, W) uint8 image.
    RuntimeError
        If ``native=True`` and the compiled module was not built.
    """
    _check_binary(binary)
    hi = np.iinfo(np.int64).max if max_len is None else int(max_len)
    if use_compiled(native, _borders, "visloc.markers._borders"):
        pts, offsets = _packed_borders(binary, int(min_len), hi)
        return [pts[a:e] for a, e in pairwise(offsets.tolist())]
    contours, holes = outer_borders(binary)
    return [contours[i].reshape(-1, 2) for i in np.flatnonzero(holes) if min_len <= len(contours[i]) <= hi]


def _check_binary(binary: NDArray) -> None:
    if binary.ndim != 2 or binary.dtype != np.uint8:
        raise ValueError(f"binary must be a (H, W) uint8 image, got {binary.shape} {binary.dtype}")


def _packed_borders(binary: NDArray[np.uint8], min_len: int,
                    max_len: int) -> tuple[NDArray[np.int32], NDArray[np.int64]]:
    """The compiled stage 4: every kept border's points (P, 2) packed, and the offsets (K + 1)."""
    b = np.ascontiguousarray(binary)
    raw, raw_offsets = _borders.enclosing_borders(b, b.shape[0], b.shape[1], min_len, max_len)
    return np.frombuffer(raw, np.int32).reshape(-1, 2), np.frombuffer(raw_offsets, np.int64)


def _packed_filter(pts: NDArray, offsets: NDArray, shape: tuple[int, ...], lo: int, hi: int,
                   params: CandidateFilter) -> tuple[list[int], NDArray[np.int32]]:
    """The compiled stage 5 on packed borders: the indices of the kept ones, and their quads (K, 4, 2)."""
    h, w = shape[:2]
    raw_kept, raw_quads = _filter.filter_quads(
        pts, offsets, w, h, (lo, hi, params.approx_rate, params.min_side, params.min_solidity,
                             params.min_compactness, params.border_distance))
    return np.frombuffer(raw_kept, np.int64).tolist(), np.frombuffer(raw_quads, np.int32).reshape(-1, 4, 2)


def find_contours(binary: NDArray[np.uint8], *, enclosing: bool = False) -> list[NDArray[np.int32]]:
    """Stage 4: the outer borders of :func:`outer_borders`.

    Parameters
    ----------
    binary : ndarray (H, W) uint8
        Binary image, ink 255 (any non-zero value), background 0
        (:func:`~visloc.markers.binarize.threshold`).
    enclosing : bool
        Return only the borders of ink regions that enclose at least one hole: a marker's
        black frame always encloses its white cells, while most texture blobs enclose
        nothing (on textured 640 x 480 frames, 41 of 1,800 outer borders).

    Returns
    -------
    list of ndarray (N, 1, 2) int32
        Each border's ``(x, y)`` pixel centres (integer coordinates), traced in order
        (OpenCV's layout).

    Raises
    ------
    ValueError
        If ``binary`` is not a (H, W) uint8 image.
    """
    contours, holes = outer_borders(binary)
    if not enclosing:
        return contours
    return [contours[i] for i in np.flatnonzero(holes)]


@dataclass(frozen=True, kw_only=True)
class CandidateFilter:
    """Bounds a contour must meet to be a marker candidate (stage 5).

    Attributes
    ----------
    min_perimeter_rate, max_perimeter_rate : float
        Contour length bounds as fractions of the searched image's larger side (OpenCV: 0.03
        and 4.0). The lower one is 0.02 here: a large frame is searched shrunk (``base_height``),
        where 0.03 of its side in contour points dropped the smallest decodable markers
        (10-14 px at 1280 x 720) that OpenCV still finds at full size.
    approx_rate : float
        Polygon approximation tolerance as a fraction of the perimeter; the contour must
        simplify to exactly four vertices (at this tolerance, or at twice it when the first
        try gives five to eight: a blob of noise touching a marker's border adds a spur, or at
        a quarter of the estimated width ``2 area / perimeter`` when it gives fewer than four:
        a marker seen nearly edge-on is thinner than the tolerance).
    min_side : float
        Shortest allowed side of that quadrilateral, px.
    min_solidity : float
        Contour area over its convex hull's area; squares seen in perspective are ~1.
    min_compactness : float
        Lower bound of ``16 * area / perimeter^2`` (1 for a square, 0.89 for a 2:1
        rectangle, 0.3 for about 11:1). 0.3 keeps markers seen nearly edge-on (a cube's side
        face in a real photo: 0.31) that 0.45 dropped; texture let through is stopped by the
        first look at the cells.
    border_distance : float
        Vertices closer than this to the image border reject the candidate (its true corner
        may lie outside the image).
    """

    min_perimeter_rate: float = 0.02
    max_perimeter_rate: float = 4.0
    approx_rate: float = 0.05
    min_side: float = 6.0
    min_solidity: float = 0.85
    min_compactness: float = 0.3
    border_distance: float = 2.0


def _on_sides(contour: NDArray, quad: NDArray, tol: float) -> float:
    """Fraction of contour points (N, 2) within ``tol`` px of the closed quad's (4, 2) sides."""
    p = contour.astype(np.float64)[:, None, :]  # (N, 1, 2)
    a = quad.astype(np.float64)
    ab = a[_NEXT] - a  # (4, 2)
    t = np.clip(((p - a) * ab).sum(axis=2) / np.maximum((ab * ab).sum(axis=1), 1e-12), 0.0, 1.0)
    d = p - (a + t[..., None] * ab)
    return float(((d * d).sum(axis=2).min(axis=1) <= tol * tol).mean())


def perimeter_bounds(image_shape: tuple[int, ...], *,
                     params: CandidateFilter = CandidateFilter()) -> tuple[int, int]:
    """Stage 5's first test: the fewest and most contour points a candidate may have.

    Parameters
    ----------
    image_shape : tuple of int
        Shape ``(H, W)`` or ``(H, W, C)`` of the searched image, px.
    params : CandidateFilter
        The bounds: ``min_perimeter_rate``, ``max_perimeter_rate`` (fractions of the larger
        side) and ``min_side`` (px; a candidate has at least about ``2.8 min_side`` points).

    Returns
    -------
    min_len, max_len : int
        Contour points, as ``min_len`` and ``max_len`` of :func:`enclosing_borders`.
    """
    size = max(image_shape[:2])
    lo = max(params.min_perimeter_rate * size, 2.8 * params.min_side)  # 8-connected: >= 2 sqrt(2) side
    return int(np.ceil(lo)), int(np.floor(params.max_perimeter_rate * size))


def filter_candidates(
    contours: list[NDArray[np.int32]],
    image_shape: tuple[int, ...],
    *,
    params: CandidateFilter = CandidateFilter(),
    native: bool | None = None,
) -> list[tuple[NDArray[np.int32], NDArray[np.int32]]]:
    """Stage 5: keep contours that may be the outer border of a square marker.

    Tests, cheapest first: contour length within the perimeter bounds relative to the image
    size; area and compactness; a four-vertex convex polygon approximation (convexity);
    every side at least ``min_side``; no vertex near the image border; solidity.

    Parameters
    ----------
    contours : list of ndarray (N, 2) or (N, 1, 2) int32
        Closed borders, ``(x, y)`` pixel centres (integer coordinates) in order
        (:func:`enclosing_borders`, :func:`find_contours`).
    image_shape : tuple of int
        Shape ``(H, W)`` or ``(H, W, C)`` of the image they were traced in, px.
    params : CandidateFilter
        The bounds of the tests.
    native : bool or None
        The compiled filter (``True``) or the OpenCV calls (``False``); ``None`` uses the
        compiled one when it was built (:data:`NATIVE_BORDERS`). Both keep the same contours
        with the same quads.

    Returns
    -------
    list of (contour, quad)
        The surviving contours as (N, 2) int32 arrays with the vertices (4, 2) int32 of their
        approximating polygon, ``(x, y)`` pixel centres, in the contour's order.

    Raises
    ------
    RuntimeError
        If ``native=True`` and the compiled module was not built.
    """
    h, w = image_shape[:2]
    lo, hi = perimeter_bounds(image_shape, params=params)
    if use_compiled(native, _filter, "visloc.markers._filter") and contours:
        return _compiled_candidates(contours, image_shape, lo, hi, params)
    return _opencv_candidates(contours, (h, w), lo, hi, params)


def _compiled_candidates(contours: list[NDArray[np.int32]], image_shape: tuple[int, ...], lo: int, hi: int,
                         params: CandidateFilter) -> list[tuple[NDArray[np.int32], NDArray[np.int32]]]:
    """:func:`filter_candidates` by the compiled filter: the (non-empty) ``contours`` packed,
    filtered with ``lo`` to ``hi`` points, each kept one as (N, 2) with its quad (4, 2)."""
    flat = [np.asarray(c).reshape(-1, 2) for c in contours]
    pts = np.ascontiguousarray(np.concatenate(flat), np.int32)
    offsets = np.concatenate([[0], np.cumsum([len(c) for c in flat])]).astype(np.int64)
    kept, quads = _packed_filter(pts, offsets, image_shape, lo, hi, params)
    return [(flat[i], quads[j]) for j, i in enumerate(kept)]


def _opencv_candidates(contours: list[NDArray[np.int32]], shape: tuple[int, int], lo: int, hi: int,
                       params: CandidateFilter) -> list[tuple[NDArray[np.int32], NDArray[np.int32]]]:
    """:func:`filter_candidates` by OpenCV calls: the ``contours`` with ``lo`` to ``hi``
    points that pass every test in an image of ``shape`` (H, W), px, each as (N, 2) with
    its quad (4, 2)."""
    h, w = shape
    lengths = np.array(list(map(len, contours)), np.int64)
    keep = np.flatnonzero((lengths >= lo) & (lengths <= hi))
    bd = params.border_distance
    min_area = params.min_side**2
    min_side2 = params.min_side**2
    out = []
    for i in keep:
        c = contours[i]
        n = len(c)
        area = cv2.contourArea(c)
        # compactness 16 A / n^2: ~1-1.6 for squares traced 8-connected, ~0 for lines and
        # ragged texture blobs; a cheap reject before the polygon approximation
        if area < min_area or 16.0 * area < params.min_compactness * n * n:
            continue
        approx = cv2.approxPolyDP(c, params.approx_rate * n, True)
        hull = -1.0
        if 4 < len(approx) <= 8:  # a small spur (noise touching the border): look coarser,
            hull = cv2.contourArea(cv2.convexHull(c))
            if area < params.min_solidity * hull:
                continue
            approx = cv2.approxPolyDP(c, 2 * params.approx_rate * n, True)
            if len(approx) == 4 and _on_sides(c.reshape(-1, 2), approx.reshape(4, 2), 0.02 * n + 1.0) < 0.8:
                continue  # ... but most of the contour must still lie on the quad's sides
        elif len(approx) < 4:  # a thin quad (seen edge-on): the tolerance exceeded its width;
            approx = cv2.approxPolyDP(c, 0.5 * area / n, True)  # a quarter of the width 2 A / n
        if len(approx) != 4 or not cv2.isContourConvex(approx):
            continue
        (x0, y0), (x1, y1), (x2, y2), (x3, y3) = approx.reshape(4, 2).tolist()
        if min(
            (x1 - x0) ** 2 + (y1 - y0) ** 2,
            (x2 - x1) ** 2 + (y2 - y1) ** 2,
            (x3 - x2) ** 2 + (y3 - y2) ** 2,
            (x0 - x3) ** 2 + (y0 - y3) ** 2,
        ) < min_side2:
            continue
        if min(x0, x1, x2, x3) < bd or min(y0, y1, y2, y3) < bd:
            continue
        if max(x0, x1, x2, x3) > w - 1 - bd or max(y0, y1, y2, y3) > h - 1 - bd:
            continue
        if hull < 0:
            hull = cv2.contourArea(cv2.convexHull(c))
        if hull <= 0 or area / hull < params.min_solidity:
            continue
        out.append((c.reshape(-1, 2), approx.reshape(4, 2)))
    return out


def find_candidates(binary: NDArray[np.uint8], *, params: CandidateFilter = CandidateFilter(),
                    native: bool | None = None) -> list[tuple[NDArray[np.int32], NDArray[np.int32]]]:
    """Stages 4 and 5 as the detector runs them: :func:`filter_candidates` on the
    :func:`enclosing_borders` of ``binary`` within :func:`perimeter_bounds`.

    The compiled route hands the packed borders of stage 4 straight to the compiled filter,
    so only the surviving borders become arrays of their own; the same (contour, quad) pairs,
    in the same order, as the two functions called one after the other.

    Parameters
    ----------
    binary : ndarray (H, W) uint8
        Binary image, ink 255 (any non-zero value), background 0
        (:func:`~visloc.markers.binarize.threshold`).
    params : CandidateFilter
        The bounds of stage 5.
    native : bool or None
        The compiled follower and filter (``True``) or the OpenCV calls (``False``);
        ``None`` uses the compiled ones when they were built (:data:`NATIVE_BORDERS`).

    Returns
    -------
    list of (contour, quad)
        As :func:`filter_candidates`: (N, 2) int32 ``(x, y)`` pixel centres of each kept
        border and the (4, 2) int32 vertices of its approximating polygon.

    Raises
    ------
    ValueError
        If ``binary`` is not a (H, W) uint8 image.
    RuntimeError
        If ``native=True`` and a compiled module was not built.
    """
    lo, hi = perimeter_bounds(binary.shape, params=params)
    if not (use_compiled(native, _borders, "visloc.markers._borders")
            and use_compiled(native, _filter, "visloc.markers._filter")):
        return filter_candidates(enclosing_borders(binary, min_len=lo, max_len=hi, native=native), binary.shape,
                                 params=params, native=native)
    _check_binary(binary)
    pts, offsets = _packed_borders(binary, lo, hi)
    if len(offsets) < 2:
        return []
    kept, quads = _packed_filter(pts, offsets, binary.shape, lo, hi, params)
    at = offsets.tolist()
    return [(pts[at[i]:at[i + 1]], quads[j]) for j, i in enumerate(kept)]
