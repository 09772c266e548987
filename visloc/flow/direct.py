"""A sub-pixel stage after the block-sum flow: direct alignment of the similarity motion.

The block-sum flow and its global-motion fit (report §3.2.2 and Appendix H) locate the image
motion to about a tenth of a pixel: the parabola through the block-matching costs limits it,
worst where the image moves less than a pixel per frame (hover, slow flight, height). This
stage refines that solution on the images themselves: inverse-compositional Gauss-Newton (the
Jacobian from the first frame's gradient, computed once) on the grey levels of the second
frame at the points of the first frame with the strongest gradients (``keep`` of a grid every
``stride`` px), moved by the similarity ``q = [[a, -b], [b, a]] p + t`` (``p`` about the image
centre, :class:`visloc.types.GlobalMotion`), with a gain and an offset of the grey levels
estimated alongside (an exposure change is not read as motion) and residuals beyond twice their
robust spread down-weighted. A step that moves the image corners by more than ``max_change``
px from the block-sum solution is not trusted: that solution is kept. The steps run in compiled
code (``visloc.flow._direct``) when it was built, else in numpy (the same result).
"""

from __future__ import annotations

import math
from dataclasses import replace

import cv2
import numpy as np
from numpy.typing import NDArray

from visloc._compiled import use_compiled
from visloc.flow.motion import _rotation_centre
from visloc.types import GlobalMotion

__all__ = ["FAST_SHIFT", "LOCAL_BOX", "NATIVE_DIRECT", "auto_stride", "blurred", "direct_options", "refine_blurred",
           "refine_motion"]

try:
    from visloc.flow import _direct
except ImportError:  # installed without a C compiler: the numpy version below
    _direct = None

#: Whether :func:`refine_motion` runs compiled code by default.
NATIVE_DIRECT = _direct is not None

_MARGIN = 8  # px of the first frame left out at its border


def refine_motion(prev: NDArray[np.uint8], curr: NDArray[np.uint8], motion: GlobalMotion, *,
                  prior: GlobalMotion | None = None, stride: int | None = None, keep: float = 0.5,
                  iterations: int = 3, tolerance: float = 0.05, max_change: float = 3.0, blur: float = 1.0,
                  native: bool | None = None) -> GlobalMotion:
    """``motion`` (the block-sum solution between the grey frames ``prev`` and ``curr``)
    refined by direct alignment (module docstring).

    Parameters
    ----------
    prev, curr : ndarray (H, W) uint8
        Consecutive grey frames of one size (under 32 px on a side: ``motion`` is returned).
    motion : GlobalMotion
        The starting solution (:func:`visloc.flow.global_motion`).
    prior : GlobalMotion, optional
        A second start, e.g. the previous pair's motion (what :class:`visloc.flow.EgoMotion`
        passes): over a periodic texture (bricks, tiles) the block sums can lock onto a
        neighbouring period, and the alignment cannot leave it. Where ``prior`` moves an image
        corner more than 1 px from ``motion``, the alignment runs from both, and the one from
        ``prior`` is kept unless its residual spread exceeds 1.25 times the other's.
    stride : int, optional
        Grid step of the candidate points, px (>= 1); by default :func:`auto_stride`: a 120th
        of the short side (2 px at 320 x 240: about 8,500 points kept at ``keep=0.5``) for
        translations under :data:`FAST_SHIFT` px per frame, where the points' noise weighs on
        the result, a 60th above (a quarter of the points and of the time).
    keep : float
        Share of the grid points kept, those with the strongest gradients, in (0, 1].
    iterations : int
        Most Gauss-Newton steps (>= 1); fewer when a step moves the translation by less than
        ``tolerance`` px.
    tolerance : float
        See ``iterations``, px. A step shrinks the remaining error about 40 times (from 0.03
        to 0.0008 px on camera-like frames), so after a step under 0.05 px about 0.001 px is
        left, well below the noise of one pair.
    max_change : float
        Largest move of an image corner from its start's, px, for the result to be trusted.
    blur : float
        Gaussian blur of both frames before the alignment, px (0: none).
    native : bool or None
        Run the compiled steps (``visloc.flow._direct``: ``True``; a ``RuntimeError`` when it
        was not built), the numpy version (``False``: the same result to about 1e-9 px, a
        dozen times slower), or the compiled one where it was built (``None``).

    Returns
    -------
    GlobalMotion
        ``method`` ``motion.method + "+direct"`` (``"+direct+prior"`` when the start from
        ``prior`` was kept), or ``motion`` itself when the alignment failed or moved too far.
    """
    if prev.shape != curr.shape or prev.ndim != 2 or prev.dtype != np.uint8 or curr.dtype != np.uint8:
        raise ValueError(f"prev and curr must be grey uint8 frames of one size, got {prev.shape} and {curr.shape}")
    h, w = prev.shape
    if min(h, w) < 4 * _MARGIN:  # too small to leave a border out: nothing to refine on
        return motion
    options = direct_options((h, w), stride=stride, keep=keep, iterations=iterations, tolerance=tolerance,
                             max_change=max_change, native=native)
    found, _ = refine_blurred((blurred(prev, sigma=blur), blurred(curr, sigma=blur)), motion, prior, options)
    return motion if found is None else found


def direct_options(shape: tuple[int, int], *, stride: int | None = None, keep: float = 0.5, iterations: int = 3,
                   tolerance: float = 0.05, max_change: float = 3.0, native: bool | None = None) -> tuple:
    """:func:`refine_motion`'s options, checked, as the tuple :func:`refine_blurred` takes.

    Parameters
    ----------
    shape : (int, int)
        ``(H, W)`` of the frames, px.
    stride, keep, iterations, tolerance, max_change, native
        As in :func:`refine_motion`.

    Returns
    -------
    tuple
        ``(stride, keep, iterations, tolerance, max_change, compiled)``; ``stride`` None:
        chosen by each alignment's start (:func:`auto_stride`).

    Raises
    ------
    ValueError
        An option out of its range.
    RuntimeError
        ``native=True`` but the compiled stage was not built.
    """
    if stride is not None and (isinstance(stride, bool) or int(stride) != stride or stride < 1):
        raise ValueError(f"stride must be an integer >= 1 or None, got {stride!r}")
    if not 0 < keep <= 1 or iterations < 1:
        raise ValueError(f"keep must be in (0, 1] and iterations >= 1; got {keep}, {iterations}")
    if not tolerance >= 0:
        raise ValueError(f"tolerance must be >= 0 px, got {tolerance!r}")
    return (None if stride is None else int(stride), float(keep), int(iterations), float(tolerance), float(max_change),
            use_compiled(native, _direct, "visloc.flow._direct"))


def refine_blurred(frames: tuple[NDArray[np.float32], NDArray[np.float32]], motion: GlobalMotion,
                   prior: GlobalMotion | None, options: tuple) -> tuple[GlobalMotion | None, float]:
    """:func:`refine_motion` on frames already blurred.

    Parameters
    ----------
    frames : (ndarray (H, W) float32, ndarray (H, W) float32)
        The first and second frame, blurred (:func:`blurred`).
    motion : GlobalMotion
        The starting solution, px.
    prior : GlobalMotion or None
        A second start (:func:`refine_motion`).
    options : tuple
        From :func:`direct_options`.

    Returns
    -------
    (GlobalMotion or None, float)
        The refined motion (None when the alignment failed or moved too far; frames under
        32 px on a side give None) and its residual spread, 1.4826 x the median absolute
        residual, grey levels (inf when it failed).
    """
    h, w = frames[0].shape
    if min(h, w) < 4 * _MARGIN:
        return None, math.inf
    found, spread = _refine_from(frames, motion, options)
    if prior is not None and _corner_shift(prior, motion, (w, h)) > 1.0:
        other, other_spread = _refine_from(frames, prior, options)
        if other is not None and (found is None or other_spread <= 1.25 * spread):
            return replace(other, method=motion.method + "+direct+prior", residual_rms=motion.residual_rms,
                           inliers=motion.inliers), other_spread
    if found is None:
        return None, math.inf
    return replace(found, method=motion.method + "+direct"), spread


def _similarity(m: GlobalMotion) -> tuple[float, float, float, float]:
    """(a, b, tx, ty) of a motion: ``q = [[a, -b], [b, a]] p + t`` about the image centre."""
    return (m.scale * math.cos(m.rotation), m.scale * math.sin(m.rotation), float(m.translation[0]),
            float(m.translation[1]))


def _corner_shift(m1: GlobalMotion, m2: GlobalMotion, size: tuple[int, int]) -> float:
    """The largest distance between where two motions move the corners of a (w, h) image, px."""
    cx, cy = (size[0] - 1) / 2.0, (size[1] - 1) / 2.0
    a, b, tx, ty = d = [p - q for p, q in zip(_similarity(m1), _similarity(m2), strict=True)]
    if not all(math.isfinite(v) for v in d):
        return math.inf
    # corner (x, y) moves to (a x - b y + tx, b x + a y + ty): the difference of the two, in floats
    return max(max(abs(a * x - b * y + tx), abs(b * x + a * y + ty))
               for x, y in ((-cx, -cy), (cx, -cy), (cx, cy), (-cx, cy)))


def _refine_from(frames: tuple[NDArray[np.float32], NDArray[np.float32]], start: GlobalMotion,
                 options: tuple) -> tuple[GlobalMotion | None, float]:
    """The alignment from ``start`` and its residual spread; None when it failed, moved an
    image corner more than ``max_change`` px from ``start`` or found an implausible gain."""
    first, second = frames
    stride, keep, iterations, tol, max_change, compiled = options
    h, w = first.shape
    if stride is None:
        stride = auto_stride((h, w), start)
    if compiled:
        *found, ok = _direct.align(first, second, h, w, _MARGIN, stride, keep, iterations, tol, *_similarity(start))
    else:
        found, ok = _align(first, second, stride, keep, iterations, tol, _similarity(start))
    if not ok:
        return None, math.inf
    a, b, tx, ty, gain, _, spread = found
    c = ((w - 1) / 2.0, (h - 1) / 2.0)
    moved = GlobalMotion(np.array([tx, ty]), math.atan2(b, a), math.hypot(a, b), _rotation_centre(a, b, tx, ty, c),
                         start.residual_rms, start.inliers, start.method)
    if _corner_shift(moved, start, (w, h)) > max_change or not 0.2 < gain < 5.0:
        return None, math.inf
    return moved, spread


#: Image translation (px per frame, at the image centre) from which :func:`auto_stride`
#: takes the coarse grid
FAST_SHIFT = 2.0


def auto_stride(shape: tuple[int, int], start: GlobalMotion) -> int:
    """The grid step of the alignment's points for a start motion: a 120th of the short
    side (2 px at 320 x 240) when ``start`` moves the image centre less than
    :data:`FAST_SHIFT` px, else a 60th (4 px at 320 x 240, a quarter of the points and of
    the time).

    In slow flight the translation is a pixel or less per frame and the noise of the points
    weighs on it (rotation is not counted: the velocity comes from the translation): on
    camera-like 320 x 240 flights (``bench/flow.py``) the fine grid gave a median relative
    error of 0.76 % in slow flight and the coarse one 1.16 %; at flight speed (with motion
    blur) 0.076 % and 0.12 %, the coarse one in under half the time.

    Parameters
    ----------
    shape : (int, int)
        ``(H, W)`` of the frames, px.
    start : GlobalMotion
        The alignment's start, px.

    Returns
    -------
    int
        The grid step, px (>= 1).
    """
    fine = math.hypot(*_similarity(start)[2:]) < FAST_SHIFT
    return max(1, round(min(shape) / (120 if fine else 60)))


#: Box (px) of the local mean a frame is divided by with ``blurred(..., local=True)``
LOCAL_BOX = 17


def blurred(img: NDArray[np.uint8], *, sigma: float = 1.0, local: bool = False) -> NDArray[np.float32]:
    """A frame as the direct alignment reads it.

    Parameters
    ----------
    img : ndarray (H, W) uint8
        Grey frame.
    sigma : float
        Gaussian blur, px (0: none; the kernel spans 2 sigma either side).
    local : bool
        Divide the frame by its local mean (a :data:`LOCAL_BOX` px box, 4 grey levels added
        against division by dark), times 128: light that varies slowly across the image (a
        shadow moving over the ground, vignetting, uneven light) then no longer reads as
        motion. On camera-like 320 x 240 flights with a moving shadow (``bench/flow.py``) the
        streamed median relative error fell from 0.90 % to 0.19 % (LK 0.84 %), the time per
        pair rose from 0.32 to 0.52 of DIS's.

    Returns
    -------
    ndarray (H, W) float32
    """
    b = img if sigma <= 0 else cv2.GaussianBlur(img, (2 * math.ceil(2 * sigma) + 1,) * 2, sigma)
    if not local:
        return b.astype(np.float32)
    gain = cv2.blur(b, (LOCAL_BOX, LOCAL_BOX)).astype(np.float32)
    gain += np.float32(4.0)
    np.divide(np.float32(128.0), gain, out=gain)  # numpy: cv2.divide with a scale is 8x slower here
    gain *= b
    return gain


def _points(first: NDArray[np.float32], stride: int, keep: float) -> tuple[NDArray, ...]:
    """The grid points (x, y about the image centre) with the strongest gradients, their grey
    levels and gradients (half the central differences). Kept: the points whose squared
    gradient (float32) is at least the threshold, the smallest of the largest ``max(6,
    int(M keep))`` values of every fourth grid point's (M), as the compiled version picks them."""
    h, w = first.shape
    ys, xs = np.mgrid[_MARGIN : h - _MARGIN : stride, _MARGIN : w - _MARGIN : stride]
    ys, xs = ys.ravel(), xs.ravel()
    gx = first[ys, xs + 1] - first[ys, xs - 1]
    gy = first[ys + 1, xs] - first[ys - 1, xs]
    mag = gx * gx + gy * gy
    sub = mag[::4]
    m_keep = max(6, int(len(sub) * keep))
    sel = mag >= (np.partition(sub, len(sub) - m_keep)[len(sub) - m_keep] if m_keep < len(sub) else -1.0)
    sel = np.flatnonzero(sel)
    ys, xs, half = ys[sel], xs[sel], np.float32(0.5)
    return (xs - (w - 1) / 2.0, ys - (h - 1) / 2.0, first[ys, xs].astype(np.float64),
            (half * gx[sel]).astype(np.float64), (half * gy[sel]).astype(np.float64))


def _sample(img: NDArray[np.float64], x: NDArray, y: NDArray) -> NDArray:
    """Bilinear samples of ``img`` at (x, y), the border replicated."""
    h, w = img.shape
    x, y = np.clip(x, -1e6, 1e6), np.clip(y, -1e6, 1e6)  # (far outside: the border pixels)
    fx, fy = np.floor(x), np.floor(y)
    ax, ay = x - fx, y - fy
    x0, y0 = fx.astype(np.intp), fy.astype(np.intp)
    x1, y1 = np.clip(x0 + 1, 0, w - 1), np.clip(y0 + 1, 0, h - 1)
    x0, y0 = np.clip(x0, 0, w - 1), np.clip(y0, 0, h - 1)
    top = (1.0 - ax) * img[y0, x0] + ax * img[y0, x1]
    bottom = (1.0 - ax) * img[y1, x0] + ax * img[y1, x1]
    return (1.0 - ay) * top + ay * bottom


def _align(first: NDArray[np.float32], second: NDArray[np.float32], stride: int, keep: float, iterations: int,
           tol: float, start: tuple[float, float, float, float]) -> tuple[list[float], bool]:
    """The numpy version of the compiled ``_direct.align``: the similarity, gain, offset and
    the last step's residual spread after the inverse-compositional Gauss-Newton steps from
    ``start`` (a, b, tx, ty), and whether they succeeded."""
    h, w = first.shape
    cx, cy = (w - 1) / 2.0, (h - 1) / 2.0
    px, py, template, tgx, tgy = _points(first, stride, keep)
    img = second.astype(np.float64)
    a, b, tx, ty = start
    gain, offset, spread = 1.0, 0.0, 0.0
    ones = np.ones(len(template))
    for _ in range(iterations):
        r = _sample(img, a * px - b * py + tx + cx, b * px + a * py + ty + cy) - (gain * template + offset)
        spread = 1.4826 * float(np.median(np.abs(r[::4]))) + 1e-6
        weight = np.minimum(1.0, 2.0 * spread / np.maximum(np.abs(r), 1e-12))
        sx, sy = gain * tgx, gain * tgy  # the first frame's gradient: inverse compositional
        J = np.stack([sx * px + sy * py, sy * px - sx * py, sx, sy, template, ones], axis=1)
        Jw = J * weight[:, None]
        try:
            d = np.linalg.solve(Jw.T @ J, Jw.T @ r)
        except np.linalg.LinAlgError:
            return [a, b, tx, ty, gain, offset, spread], False
        ma, mb = 1.0 + d[0], d[1]
        det = ma * ma + mb * mb
        if not (np.all(np.isfinite(d)) and det > 0):
            return [a, b, tx, ty, gain, offset, spread], False
        ia, ib = ma / det, -mb / det  # the step's inverse, composed: A M^-1, t - A M^-1 dt
        na, nb = a * ia - b * ib, a * ib + b * ia
        ntx, nty = tx - (na * d[2] - nb * d[3]), ty - (nb * d[2] + na * d[3])
        moved = abs(ntx - tx) + abs(nty - ty)
        a, b, tx, ty, gain, offset = na, nb, ntx, nty, gain + d[4], offset + d[5]
        if moved < tol:
            break
    return [a, b, tx, ty, gain, offset, spread], True
