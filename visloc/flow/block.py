"""Block-sum optical flow (report §3.2.2 "Optical Flow", after its ref. [8], EdgeFlow).

Report §3.2.2: "the rows and columns are block-wise (40 x 40 pixels) summed such that two (an x
and an y) vector are obtained. This is done for two consecutive frames ... the corresponding
vectors are correlated ..., resulting in a shift representing the best correspondence."

Per block: the column sums of its rows give an x profile, the row sums of its columns a y
profile (in ``"gradient"`` mode their derivative, as EdgeFlow does, which ignores brightness
offsets; in ``"intensity"`` mode the sums with each window's mean removed, as the report
does). Each profile of the first frame is matched against the second frame's by the sum of
squared differences over a search range; a Gauss-Newton step on the profile around the cost
minimum gives the sub-pixel shift. First the whole image's profiles are matched over a wide
range, and the second frame's bands are taken that much further along, so each block searches
only a small range around the global shift: fast motion stays in reach at little cost. (The
global match uses the central third of the image only: far from the centre a yaw rotation
moves the content across the bands and smears the long profiles.) All band sums, shifted or
not, are read off one summed-area table (``cv2.integral``) per frame; all blocks and both
directions are matched in one batch.
"""

from __future__ import annotations

from functools import lru_cache
from typing import NamedTuple

import cv2
import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import NDArray

from visloc.images import as_gray
from visloc.types import FlowField

__all__ = ["MODES", "block_flow", "check_pair", "default_block"]

#: Profile kinds :func:`block_flow` matches.
MODES = ("gradient", "intensity")


def check_pair(prev: object, curr: object) -> tuple[NDArray[np.uint8], NDArray[np.uint8]]:
    """Both frames as grey uint8 images of the same size (at least 16 x 16).

    Parameters
    ----------
    prev, curr : ndarray (H, W) or (H, W, 3) uint8
        Consecutive frames (BGR frames are turned grey).

    Returns
    -------
    (ndarray (H, W) uint8, ndarray (H, W) uint8)
        The grey frames.

    Raises
    ------
    TypeError, ValueError
        A frame that is not an image, of another size than the other, or smaller than 16 x 16.
    """
    a = as_gray(prev, name="prev")
    b = as_gray(curr, name="curr")
    if a.shape != b.shape:
        raise ValueError(f"prev and curr must have the same size, got {a.shape[::-1]} and {b.shape[::-1]} (W, H)")
    if min(a.shape) < 16:
        raise ValueError(f"frames must be at least 16 x 16 pixels, got {a.shape[::-1]} (W, H)")
    return a, b


def default_block(shape: tuple[int, ...]) -> int:
    """Block side for frames of ``shape``: the report's 40 px at 320 x 240, growing with the
    fourth root of the short side above that (48 px at 640 x 480: more, smaller blocks measure
    large frames better, see ``bench/flow.py``), at most a sixth of the short side, even, in
    [16, 64].

    Parameters
    ----------
    shape : tuple of int
        ``(H, W, ...)`` of the frames, px.

    Returns
    -------
    int
        Block side, px.
    """
    return _block_for(int(min(shape[:2])))


@lru_cache(maxsize=64)
def _block_for(short: int) -> int:
    side = min(40.0 * (short / 240.0) ** 0.25, short / 6.0)
    return min(64, max(16, round(side / 2.0) * 2))


def _integral(img: NDArray[np.uint8]) -> NDArray:
    """Summed-area table (H + 1, W + 1) of a grey image (int32 while no sum can overflow)."""
    return cv2.integral(img, sdepth=cv2.CV_32S if img.size * 255 < 2**31 else cv2.CV_64F)


def _band_sums(ii: NDArray, img: NDArray[np.uint8], start: int, step: int, count: int, length: int,
               axis: int) -> NDArray:
    """Sums (count, length) over the bands of rows (``axis=0``) or columns (``axis=1``)
    ``[start + j step, start + (j + 1) step)`` of ``img`` (H, W), for each of its first
    ``length`` columns (rows), from its summed-area table ``ii`` (H + 1, W + 1); rows
    (columns) outside the image repeat its edge rows (columns)."""
    n = img.shape[axis]
    stop = start + count * step
    if axis == 0:
        if start >= 0 and stop <= n:
            cum = ii[start : stop + 1 : step, : length + 1]
        else:
            cum = ii[:, : length + 1].take(np.arange(start, stop + 1, step), axis=0, mode="clip")
        d = cum[1:] - cum[:-1]
        sums = d[:, 1:] - d[:, :-1]
        first, last = img[0, :length], img[n - 1, :length]
    else:
        cum = ii[: length + 1].take(np.arange(start, stop + 1, step), axis=1, mode="clip")
        d = cum[:, 1:] - cum[:, :-1]
        sums = (d[1:] - d[:-1]).T
        first, last = img[:length, 0], img[:length, n - 1]
    j = 0
    while start + j * step < 0 and j < count:  # bands reaching before the image: its first row repeated
        sums[j] += min(-(start + j * step), step) * first.astype(sums.dtype)
        j += 1
    j = count - 1
    while start + (j + 1) * step > n and j >= 0:  # bands reaching past it: its last row repeated
        sums[j] += min(start + (j + 1) * step - n, step) * last.astype(sums.dtype)
        j -= 1
    return sums


def _groups(ii: NDArray, img: NDArray[np.uint8], step: int, rows: int, cols: int, sx: int = 0,
            sy: int = 0) -> tuple[NDArray, NDArray]:
    """Sums of every ``step`` rows (``gx``: (rows/step, cols)) and of every ``step`` columns
    (``gy``: (cols/step, rows)) of ``img`` with summed-area table ``ii``, the rows taken ``sy``
    lower and the columns ``sx`` further right (edge pixels repeated). (Sums, not means: every
    use of them, the matching costs, their ratios and the texture relative to its median, is
    free of scale.)"""
    return (_band_sums(ii, img, sy, step, rows // step, cols, 0),
            _band_sums(ii, img, sx, step, cols // step, rows, 1))


def _global_profiles(ii: NDArray, y0: int, y1: int, x0: int, x1: int, rows: int, cols: int,
                     gradient: bool) -> tuple[NDArray, NDArray]:
    """Column sums over rows ``y0 .. y1 - 1`` (x profile, ``cols`` long) and row sums over
    columns ``x0 .. x1 - 1`` (y profile, ``rows`` long) from a summed-area table, as float64
    (whole numbers), differentiated if asked."""
    out = []
    for cum in (ii[y1, : cols + 1] - ii[y0, : cols + 1], ii[: rows + 1, x1] - ii[: rows + 1, x0]):
        prof = cum[1:] - cum[:-1]
        if gradient:
            prof = prof[1:] - prof[:-1]
        out.append(prof.astype(np.float64))
    return out[0], out[1]


@lru_cache(maxsize=32)
def _ones(m: int) -> NDArray:
    """A read-only float64 row of ``m`` ones (cached)."""
    ones = np.ones(m)
    ones.setflags(write=False)
    return ones


def _global_shift(p: NDArray, q: NDArray, search: int, near: int | None = None) -> int:
    """Integer d in [-S, S] minimising the sum of squared differences of the central part
    ``p[S : n - S]`` of ``p`` and ``q`` taken ``d`` further along (``S = min(search, n // 3)``),
    every shift compared over the same number of samples: ``sum q^2`` over each window
    minus twice the correlation (``p``'s own energy is the same for every shift); exact for
    the whole-numbered profiles of :func:`_global_profiles`. With ``near``, only the shifts
    within :data:`PRIOR_SEARCH` of it are candidates (when any lies in [-S, S])."""
    n = len(p)
    s = min(search, n // 3)
    cost = np.correlate(q * q, _ones(n - 2 * s), "valid") - 2.0 * np.correlate(q, p[s : n - s], "valid")
    if near is not None:
        lo, hi = max(near - PRIOR_SEARCH, -s), min(near + PRIOR_SEARCH, s)
        if lo <= hi:
            return int(cost[lo + s : hi + s + 1].argmin()) + lo
    return int(cost.argmin()) - s


def _windows(a: NDArray, length: int) -> NDArray:
    """Read-only view (rows, n - length + 1, length) of every window of each row of ``a`` (C-contiguous)."""
    rows, n = a.shape
    view = np.ndarray((rows, n - length + 1, length), a.dtype, a, 0, (a.strides[0], a.strides[1], a.strides[1]))
    view.flags.writeable = False
    return view


def _profile(g: NDArray, k: int, gradient: bool, out: NDArray) -> None:
    """Band sums of ``k`` consecutive groups into ``out``, differentiated along the profile if asked."""
    bands = g if k == 1 else (g[:-1] + g[1:] if k == 2 else sliding_window_view(g, k, axis=0).sum(axis=-1))
    if gradient:
        np.subtract(bands[:, 1:], bands[:, :-1], out=out)
    else:
        out[...] = bands


#: Half-width (px) of the whole-image search around a ``prior`` shift (:func:`block_flow`):
#: at 60 frames per second the image motion changes by well under a pixel from one pair to the next
PRIOR_SEARCH = 3

_NEIGHBOURS = np.array([-1, 0, 1])
_BIG = np.float32(1e30)  # the cost of a shift outside the frame (finite: no NaN from inf - inf)


def _best_shifts(cost: NDArray, i: NDArray, p_seg: NDArray, q3: NDArray, r: NDArray) -> tuple[NDArray, NDArray]:
    """Sub-pixel offset and ambiguity ratio of every segment's best integer shift.

    ``cost`` (D, S) holds each segment's matching cost per shift, ``_BIG`` where a shift
    leaves the frame and in the first and last row (the shifts just beyond the search range,
    so that the best one always has two neighbours); ``i`` (S,) is its argmin over the
    shifts; ``q3`` (S, 3, L) holds the second frame's segments one step before, at and one
    step after the best shift; ``r`` is ``arange(S)``. The offset is one Gauss-Newton step on
    the squared difference around the best shift, ``s = -sum(g r) / sum(g^2)`` with
    ``r = q - p`` there and ``g`` the profile's derivative (exact for a pure shift of a linear
    profile, and exactly 0 for identical frames, where a parabola through the costs is
    biased). The ratio is the best cost over the best one at least two steps away: 0 for an
    unambiguous minimum, 1 for none (or one at the end of the search range, or without
    curvature).
    """
    im, ip = i - 1, i + 1  # inside the array unless every cost is _BIG (then im = -1: no harm)
    c0, cm, cp = cost[i, r], cost[im, r], cost[ip, r]
    rest = cost.copy()  # the best cost at least two steps away
    rest[i, r] = rest[im, r] = rest[ip, r] = _BIG
    second = rest.min(axis=0)
    g = q3[:, 2] - q3[:, 0]  # twice the derivative
    step = 2.0 * np.vecdot(g, p_seg - q3[:, 1]) / np.maximum(np.vecdot(g, g), 1e-12)  # 0 where g = 0
    # a proper inner minimum: neighbours inside the frame and the search range, curved
    good = (np.maximum(cm, cp) < _BIG) & (cm + cp > 2.0 * c0)
    ratio = np.where(good & (second > 0) & (second < _BIG), c0 / np.maximum(second, 1e-30), 1.0)
    off = np.where(good, np.minimum(np.maximum(step, -0.75), 0.75), 0.0)
    return off, ratio


class _Layout(NamedTuple):
    nby: int
    nbx: int
    length: int  # profile row length: max(rows, cols), a whole number of steps
    band: NDArray  # (S,) row of the stacked profile array of each segment
    chunk: NDArray  # (S,) its first step-long chunk of that row (start // step)
    start: NDArray  # (S,) first profile sample of each segment
    limit: NDArray  # (S,) last valid start in the second frame
    is_x: NDArray  # (S,) x segments first, then y segments
    d: NDArray  # (D,) search offsets, one beyond the range at each end
    centers: NDArray  # (N, 2) block centres
    index: NDArray  # (S,) 0 .. S - 1, the segments' own indices
    whole: NDArray  # (step,) ones: the sum over a chunk
    partial: NDArray  # (step,) ones for the samples of a segment's last, partial chunk


@lru_cache(maxsize=16)
def _layout(rows: int, cols: int, bsz: int, stp: int, srch: int, lx: int, ly: int, seg_len: int) -> _Layout:
    """Block and segment indices for one frame geometry (cached: a stream reuses them)."""
    xs = np.arange(0, cols - bsz + 1, stp)
    ys = np.arange(0, rows - bsz + 1, stp)
    nby, nbx = len(ys), len(xs)
    rr, cc = np.meshgrid(np.arange(nby), np.arange(nbx), indexing="ij")  # block (r, c)
    n = rr.size
    band = np.concatenate([rr.ravel(), nby + cc.ravel()])  # x segments, then y segments
    start = np.concatenate([xs[cc.ravel()], ys[rr.ravel()]])
    limit = np.concatenate([np.full(n, lx - seg_len), np.full(n, ly - seg_len)])
    is_x = np.arange(2 * n) < n
    centers = (np.stack([xs[cc.ravel()], ys[rr.ravel()]], axis=1) + (bsz - 1) / 2.0).astype(np.float64)
    index = np.arange(2 * n)
    whole = np.ones(stp, np.float32)
    partial = (np.arange(stp) < seg_len % stp).astype(np.float32)
    chunk = start // stp
    for arr in (band, chunk, start, limit, is_x, centers, index, whole, partial):
        arr.setflags(write=False)
    return _Layout(nby, nbx, max(rows, cols), band, chunk, start, limit, is_x, np.arange(-srch - 1, srch + 2),
                   centers, index, whole, partial)


class _Search(NamedTuple):
    moved: NDArray  # (D, S) the displacement each shift stands for: global shift + offset
    ok: NDArray  # (D, S) False where that shift takes the segment off the profile


@lru_cache(maxsize=512)
def _search(key: tuple[int, ...], sx: int, sy: int) -> _Search:
    """Which shifts of every segment of the layout ``_layout(*key)`` stay on the second
    frame's profile for the global shift (sx, sy) (cached: shifts repeat from frame to frame)."""
    lay = _layout(*key)
    shift = np.where(lay.is_x, sx, sy)
    pos = (lay.start + shift)[:, None] + lay.d[None, :]
    ok = (pos >= 0) & (pos <= lay.limit[:, None])
    ok[:, [0, -1]] = False  # the shifts just beyond the search range: see _best_shifts
    moved = (shift[:, None] + lay.d[None, :]).astype(np.float64)
    moved, ok = moved.T.copy(), ok.T.copy()
    for arr in (moved, ok):
        arr.setflags(write=False)
    return _Search(moved, ok)


def _segment_sums(e: NDArray, lay: _Layout, k: int, seg_len: int) -> NDArray:
    """Sums (rows, D, segments) over every block's segment of ``e`` (rows, D, length): segment
    j covers samples ``[j step, j step + seg_len)``, i.e. ``seg_len // step`` whole chunks of
    ``step`` samples and the first ``seg_len % step`` samples of the next one (``k`` =
    block / step chunks per block)."""
    stp = len(lay.partial)
    whole, part = divmod(seg_len, stp)
    chunks = e.reshape(-1, stp)
    shape = (e.shape[0], e.shape[1], -1)
    nseg = e.shape[2] // stp - k + 1
    if whole == 0:  # the default: blocks side by side, gradient segments one sample short
        return (chunks @ lay.partial).reshape(shape)[..., :nseg]
    full = (chunks @ lay.whole).reshape(shape)
    out = full[..., :nseg].copy()
    for m in range(1, whole):
        out += full[..., m : m + nseg]
    if part:
        out += (chunks @ lay.partial).reshape(shape)[..., whole : whole + nseg]
    return out


def block_flow(
    prev: NDArray[np.uint8],
    curr: NDArray[np.uint8],
    *,
    block: int | None = None,
    step: int | None = None,
    search: int | None = None,
    global_search: int | None = None,
    mode: str = "gradient",
    prior: tuple[float, float] | None = None,
) -> FlowField:
    """Optical flow of image blocks from row and column band sums (report §3.2.2).

    Parameters
    ----------
    prev, curr : ndarray (H, W) or (H, W, 3) uint8
        Consecutive frames of the same size.
    block : int, optional
        Block side, px (default :func:`default_block`: 40 at 320 x 240, as in the report).
    step : int, optional
        Distance between block origins, px; ``block`` must be a multiple of it (default
        ``block``: side by side; ``block // 2`` overlaps them by half).
    search : int, optional
        Per-block search range around the global shift, px (default ``block // 8``, at least
        3: rotation and parallax on top of the global shift).
    global_search : int, optional
        Search range of the whole-image match, px (default a quarter of the short side).
    mode : {"gradient", "intensity"}
        Match the derivative of the band sums (EdgeFlow) or the sums themselves (the report).
    prior : (dx, dy), optional
        The expected content displacement, px (e.g. the previous pair's, as
        :class:`visloc.flow.EgoMotion` passes it): the whole-image match then only considers
        shifts within :data:`PRIOR_SEARCH` px of it, so that over a periodic texture (bricks,
        tiles) it does not lock onto a neighbouring period.

    Returns
    -------
    FlowField
        Block centres, content displacement (dx, dy) from ``prev`` to ``curr``, confidence
        (0 for blocks without texture or with an ambiguous or out-of-range match).
    """
    a, b_img = check_pair(prev, curr)
    _check_mode_and_prior(mode, prior)
    h, w = a.shape
    bsz, stp, srch, gsrch = _sizes(a.shape, block, step, search, global_search)
    rows, cols = (h // stp) * stp, (w // stp) * stp
    k = bsz // stp
    grad = mode == "gradient"
    ia, ib = _integral(a), _integral(b_img)
    gxa, gya = _groups(ia, a, stp, rows, cols)
    sx, sy = _global_shifts(ia, ib, (len(gxa), len(gya)), stp, rows, cols, grad, gsrch, prior)
    gxb, gyb = _groups(ib, b_img, stp, rows, cols, sx, sy)
    # every block's x profile (from its rows' band) and y profile (from its columns' band),
    # as one list of segments: band row, start, and the second frame's offset for each
    seg_len = bsz - 1 if grad else bsz
    lx, ly = cols - grad, rows - grad  # profile lengths
    key = (rows, cols, bsz, stp, srch, lx, ly, seg_len)
    lay = _layout(*key)
    pad = srch + 1 + max(abs(sx), abs(sy))
    P, Q = _stacked_profiles((gxa, gya, gxb, gyb), lay, k, grad, pad, (sx, sy), (lx, ly))
    moved, ok = _search(key, sx, sy)  # which shifts keep each segment on the profile
    d0 = pad + int(lay.d[0])
    cost = _costs(P, Q, lay, d0, k, seg_len, grad, ok)
    best = cost.argmin(axis=0)
    p_seg, q3 = _matched_segments(P, Q, lay, best, d0, seg_len, grad)
    off, ratio = _best_shifts(cost, best, p_seg, q3, lay.index)
    disp = moved[best, lay.index] + off  # (S,): x segments, then y segments
    return FlowField(lay.centers, disp.reshape(2, -1).T.copy(), _confidence(p_seg, ratio), bsz, (w, h))


def _check_mode_and_prior(mode: str, prior: tuple[float, float] | None) -> None:
    """:func:`block_flow`'s ``mode`` and ``prior`` checked (a ValueError naming the bad one)."""
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    if prior is not None and (np.shape(prior) != (2,) or not np.isfinite(np.asarray(prior, np.float64)).all()):
        raise ValueError(f"prior must be two finite numbers (dx, dy) in px, got {prior!r}")


def _global_shifts(ia: NDArray, ib: NDArray, groups: tuple[int, int], stp: int, rows: int, cols: int,
                   grad: bool, gsrch: int, prior: tuple[float, float] | None) -> tuple[int, int]:
    """Whole-image integer shift (sx, sy), px, of the second frame's content from the
    summed-area tables ``ia`` and ``ib`` of both frames (``groups``: the number of ``stp``-px
    row and column groups), searched within ``gsrch`` px (near ``prior`` when given)."""
    # global shift from the central third of the rows (columns): a yaw rotation smears the
    # profile of a band by its length times the angle, so the band is kept short
    ny, nx = groups
    r0, r1, c0, c1 = ny // 3, ny - ny // 3, nx // 3, nx - nx // 3
    ga = _global_profiles(ia, r0 * stp, r1 * stp, c0 * stp, c1 * stp, rows, cols, grad)
    gb = _global_profiles(ib, r0 * stp, r1 * stp, c0 * stp, c1 * stp, rows, cols, grad)
    near = (None, None) if prior is None else (round(float(prior[0])), round(float(prior[1])))
    sx = _global_shift(ga[0], gb[0], gsrch, near[0])
    sy = _global_shift(ga[1], gb[1], gsrch, near[1])
    return sx, sy


def _stacked_profiles(groups: tuple[NDArray, NDArray, NDArray, NDArray], lay: _Layout, k: int, grad: bool,
                      pad: int, shift: tuple[int, int], lengths: tuple[int, int]) -> tuple[NDArray, NDArray]:
    """The profiles of both frames from their band sums ``groups`` (gxa, gya, gxb, gyb), one
    row per band: ``P`` (bands, length) of the first frame, ``Q`` (bands, length + 2 pad) of
    the second, placed ``pad`` minus the global ``shift`` (sx, sy) px along; ``lengths``:
    the x and y profiles' lengths (lx, ly)."""
    gxa, gya, gxb, gyb = groups
    (sx, sy), (lx, ly) = shift, lengths
    nby, nb = lay.nby, lay.nby + lay.nbx
    # the first frame's profiles P (one row per band: x profiles of the row bands, then y
    # profiles of the column bands) and the second frame's, Q, placed in a wider array so that
    # one window offset per search step serves both directions: Q[b, pad + x + d] is the second
    # frame's sample x + d along the profile further than the global shift of its direction
    dtype = np.float32 if grad else np.float64  # (intensity costs subtract large sums)
    P = np.zeros((nb, lay.length), dtype)
    Q = np.zeros((nb, lay.length + 2 * pad), dtype)
    _profile(gxa, k, grad, P[:nby, :lx])
    _profile(gya, k, grad, P[nby:, :ly])
    _profile(gxb, k, grad, Q[:nby, pad - sx : pad - sx + lx])
    _profile(gyb, k, grad, Q[nby:, pad - sy : pad - sy + ly])
    return P, Q


def _costs(P: NDArray, Q: NDArray, lay: _Layout, d0: int, k: int, seg_len: int, grad: bool,
           ok: NDArray) -> NDArray:
    """Matching cost (D, S) of every segment at every search offset: the sum of squared
    differences of its profile in ``P`` and ``Q`` (in intensity mode with each window's mean
    removed), ``_BIG`` where ``ok`` is False; ``d0`` is the offset in ``Q`` of the first shift."""
    e = _windows(Q, lay.length)[:, d0 : d0 + len(lay.d)] - P[:, None, :]  # (nb, D, length)
    if grad:
        np.multiply(e, e, out=e)
        sums = _segment_sums(e, lay, k, seg_len)  # sums of squared differences
    else:  # with each window's mean removed: sum (e - mean e)^2 = sum e^2 - (sum e)^2 / L
        s1 = _segment_sums(e, lay, k, seg_len)
        np.multiply(e, e, out=e)
        sums = _segment_sums(e, lay, k, seg_len) - s1 * s1 / seg_len
    return np.where(ok, sums.transpose(1, 0, 2)[:, lay.band, lay.chunk], _BIG)  # (D, S)


def _matched_segments(P: NDArray, Q: NDArray, lay: _Layout, best: NDArray, d0: int, seg_len: int,
                      grad: bool) -> tuple[NDArray, NDArray]:
    """Each segment's first-frame profile ``p_seg`` (S, L) and the second frame's one step
    before, at and after its best shift ``best`` (S,) ``q3`` (S, 3, L) (``d0``: the offset in
    ``Q`` of the first shift), with their means removed in intensity mode."""
    p_seg = _windows(P, seg_len)[lay.band, lay.start]  # (S, L)
    q3 = _windows(Q, seg_len)[lay.band[:, None], (lay.start + best + d0)[:, None] + _NEIGHBOURS]  # (S, 3, L)
    if not grad:
        p_seg = p_seg - p_seg.mean(axis=1, keepdims=True)
        q3 = q3 - q3.mean(axis=2, keepdims=True)
    return p_seg, q3


def _sizes(shape: tuple[int, int], block: int | None, step: int | None, search: int | None,
           global_search: int | None) -> tuple[int, int, int, int]:
    """:func:`block_flow`'s block, step, search and global search (px) for frames of
    ``shape``, the defaults filled in; a ValueError naming the first out of its range."""
    h, w = shape
    bsz = default_block(shape) if block is None else int(block)
    stp = bsz if step is None else int(step)
    if not 8 <= bsz <= min(h, w):
        raise ValueError(f"block must be in [8, {min(h, w)}] px for {w} x {h} frames, got {bsz}")
    if stp < 1 or bsz % stp:
        raise ValueError(f"step must divide block ({bsz}), got {stp}")
    srch = max(3, bsz // 8) if search is None else int(search)
    gsrch = max(srch, min(h, w) // 4) if global_search is None else int(global_search)
    if srch < 1 or gsrch < 1:
        raise ValueError(f"search ranges must be >= 1, got search={srch}, global_search={gsrch}")
    return bsz, stp, srch, gsrch


def _confidence(p_seg: NDArray, ratio: NDArray) -> NDArray[np.float64]:
    """Each block's confidence from its x and y segments (the first frame's profiles
    ``p_seg`` (S, L) and the best-to-runner-up cost ``ratio`` (S,), x segments then y): the
    worse direction's ``1 - ratio`` times its texture relative to the median block's (at most 1)."""
    texture = np.vecdot(p_seg, p_seg).reshape(2, -1).min(axis=0)
    ratio = ratio.reshape(2, -1).max(axis=0)
    half = texture.size // 2
    ref = float(np.partition(texture, half)[half]) if texture.size else 0.0  # median
    conf = (1.0 - ratio) * (np.minimum(texture / ref, 1.0) if ref > 0 else 0.0)  # ratio is in [0, 1]
    return conf.astype(np.float64)
