"""A sub-pixel stage after the block-sum flow: direct alignment of the similarity motion.

The block-sum flow and its global-motion fit (report §3.2.2 and Appendix H) locate the image
motion to about a tenth of a pixel: the parabola through the block-matching costs limits it,
worst where the image moves less than a pixel per frame (hover, slow flight, height). This
stage refines that solution on the images themselves: Gauss-Newton on the grey levels of the
second frame at the points of the first frame with the strongest gradients (``keep`` of a grid
every ``stride`` px), moved by the similarity ``q = [[a, -b], [b, a]] p + t`` (``p`` about the
image centre, :class:`visloc.types.GlobalMotion`), with a gain and an offset of the grey levels
estimated alongside (an exposure change is not read as motion) and residuals beyond twice their
robust spread down-weighted. A step that moves the image corners by more than
``max_change`` px from the block-sum solution is not trusted: that solution is kept.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
from numpy.typing import NDArray

from visloc.flow.motion import _rotation_centre
from visloc.types import GlobalMotion

__all__ = ["refine_motion"]

_MARGIN = 8  # px of the first frame left out at its border
_OFFSETS_X = np.array([0.0, 0.5, -0.5, 0.0, 0.0], np.float32)  # the sample, then half a pixel either side
_OFFSETS_Y = np.array([0.0, 0.0, 0.0, 0.5, -0.5], np.float32)


def refine_motion(prev: NDArray[np.uint8], curr: NDArray[np.uint8], motion: GlobalMotion, *, stride: int = 4,
                  keep: float = 0.5, iterations: int = 3, max_change: float = 3.0) -> GlobalMotion:
    """``motion`` (the block-sum solution between the grey frames ``prev`` and ``curr``)
    refined by direct alignment (module docstring).

    Parameters
    ----------
    prev, curr : ndarray (H, W) uint8
        Consecutive grey frames of one size (under 32 px on a side: ``motion`` is returned).
    motion : GlobalMotion
        The starting solution (:func:`visloc.flow.global_motion`).
    stride : int
        Grid step of the candidate points, px (>= 1).
    keep : float
        Share of the grid points kept, those with the strongest gradients, in (0, 1].
    iterations : int
        Most Gauss-Newton steps (>= 1); fewer when a step moves the translation by less than
        0.002 px.
    max_change : float
        Largest move of an image corner from ``motion``'s, px, for the result to be trusted.

    Returns
    -------
    GlobalMotion
        ``method`` ``motion.method + "+direct"``, or ``motion`` itself when the alignment failed
        or moved too far.
    """
    if prev.shape != curr.shape or prev.ndim != 2 or prev.dtype != np.uint8 or curr.dtype != np.uint8:
        raise ValueError(f"prev and curr must be grey uint8 frames of one size, got {prev.shape} and {curr.shape}")
    h, w = prev.shape
    if min(h, w) < 4 * _MARGIN:  # too small to leave a border out: nothing to refine on
        return motion
    if isinstance(stride, bool) or int(stride) != stride or stride < 1 or not 0 < keep <= 1 or iterations < 1:
        raise ValueError(f"stride must be an integer >= 1, keep in (0, 1], iterations >= 1; got {stride}, {keep}, "
                         f"{iterations}")
    c = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
    first = cv2.GaussianBlur(prev, (5, 5), 1.0).astype(np.float32)
    second = cv2.GaussianBlur(curr, (5, 5), 1.0).astype(np.float32)
    ys, xs = np.mgrid[_MARGIN : h - _MARGIN : int(stride), _MARGIN : w - _MARGIN : int(stride)]
    ys, xs = ys.ravel(), xs.ravel()
    gx = first[ys, xs + 1] - first[ys, xs - 1]
    gy = first[ys + 1, xs] - first[ys - 1, xs]
    mag = gx * gx + gy * gy
    n_keep = max(6, int(len(mag) * keep))
    if n_keep >= len(mag):
        sel = np.arange(len(mag))
    else:
        sel = np.argpartition(mag, len(mag) - n_keep)[len(mag) - n_keep :]
    px, py = xs[sel] - c[0], ys[sel] - c[1]
    template = first[ys[sel], xs[sel]].astype(np.float64)
    a, b = motion.scale * math.cos(motion.rotation), motion.scale * math.sin(motion.rotation)
    tx, ty = float(motion.translation[0]), float(motion.translation[1])
    gain, offset = 1.0, 0.0
    ones = np.ones(len(template))
    for _ in range(int(iterations)):
        qx = (a * px - b * py + tx + c[0]).astype(np.float32)
        qy = (b * px + a * py + ty + c[1]).astype(np.float32)
        s = cv2.remap(second, qx[None, :] + _OFFSETS_X[:, None], qy[None, :] + _OFFSETS_Y[:, None], cv2.INTER_LINEAR,
                      borderMode=cv2.BORDER_REPLICATE).astype(np.float64)
        sx, sy = s[1] - s[2], s[3] - s[4]  # the second frame's gradient at the moved points
        r = s[0] - (gain * template + offset)
        spread = 1.4826 * float(np.median(np.abs(r))) + 1e-6
        weight = np.minimum(1.0, 2.0 * spread / np.maximum(np.abs(r), 1e-12))
        J = np.stack([sx * px + sy * py, sy * px - sx * py, sx, sy, -template, -ones], axis=1)
        Jw = J * weight[:, None]
        try:
            d = np.linalg.solve(Jw.T @ J, -(Jw.T @ r))
        except np.linalg.LinAlgError:
            return motion
        if not np.all(np.isfinite(d)):
            return motion
        a, b, tx, ty, gain, offset = a + d[0], b + d[1], tx + d[2], ty + d[3], gain + d[4], offset + d[5]
        if abs(d[2]) + abs(d[3]) < 2e-3:
            break
    corners = np.array([[-c[0], -c[1]], [c[0], -c[1]], [c[0], c[1]], [-c[0], c[1]]])
    a0, b0 = motion.scale * math.cos(motion.rotation), motion.scale * math.sin(motion.rotation)

    def moved(a_: float, b_: float, t: tuple[float, float]) -> NDArray:
        return corners @ np.array([[a_, b_], [-b_, a_]]) + np.asarray(t)

    change = np.abs(moved(a, b, (tx, ty)) - moved(a0, b0, tuple(motion.translation))).max()
    if not np.isfinite(change) or change > max_change or not 0.2 < gain < 5.0:
        return motion
    return GlobalMotion(np.array([tx, ty]), math.atan2(b, a), math.hypot(a, b),
                        _rotation_centre(a, b, tx, ty, (c[0], c[1])), motion.residual_rms, motion.inliers,
                        motion.method + "+direct")
