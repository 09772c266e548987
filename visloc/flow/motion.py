"""Global motion from a flow field: the report's centre of instantaneous rotation (Appendix H)
and a robust similarity fit.

Both describe the image content's motion between two frames as a rotation by ``gamma`` about a
centre plus nothing else (Appendix H) or, equivalently, a rotation about the image centre plus
a translation (the similarity fit, which also has a scale).
"""

from __future__ import annotations

import math
import numbers

import numpy as np
from numpy.typing import NDArray

from visloc.types import FlowField, GlobalMotion

__all__ = ["METHODS", "global_motion", "instantaneous_rotation", "similarity_fit"]

#: Solvers :func:`global_motion` offers.
METHODS = ("similarity", "cir")

_MIN_ROTATION = 1e-6  # rad: below this the centre of rotation is taken to be at infinity
_FAR = 20.0  # a centre farther than this many image diagonals is taken to be at infinity


def _image_center(field: FlowField) -> NDArray[np.float64]:
    w, h = field.image_size
    return np.array([(w - 1) / 2.0, (h - 1) / 2.0])


def _similarity_from_gram(g: NDArray) -> tuple[float, float, float, float]:
    """(a, b, tx, ty) of the weighted least-squares similarity ``q = [[a, -b], [b, a]] p + t``
    from the weighted Gram matrix ``g = X^T W X`` (5, 5) of the rows ``X = [1, px, py, qx, qy]``
    (moments centred by subtracting the weighted means)."""
    (sw, spx, spy, sqx, sqy), (_, sxx, _, sxqx, sxqy), (_, _, syy, syqx, syqy) = g[:3].tolist()
    mpx, mpy, mqx, mqy = spx / sw, spy / sw, sqx / sw, sqy / sw
    den = sxx + syy - sw * (mpx * mpx + mpy * mpy)
    if den <= 1e-12:  # all points at one place: translation only
        return 1.0, 0.0, mqx - mpx, mqy - mpy
    a = (sxqx + syqy - sw * (mpx * mqx + mpy * mqy)) / den
    b = (sxqy - syqx - sw * (mpx * mqy - mpy * mqx)) / den
    return a, b, mqx - (a * mpx - b * mpy), mqy - (b * mpx + a * mpy)


def similarity_fit(field: FlowField, *, min_confidence: float = 0.2, iterations: int = 3) -> GlobalMotion:
    """Robust weighted least-squares similarity (rotation, scale, translation) of a flow field.

    Blocks are weighted by their confidence; after each fit, blocks whose residual exceeds
    3 times the robust spread (1.4826 x the median residual, at least 0.1 px) are dropped,
    until the set of blocks no longer changes.

    Parameters
    ----------
    field : FlowField
        Block flow (:func:`visloc.flow.block_flow`), px.
    min_confidence : float
        Blocks of lower confidence are left out.
    iterations : int
        Most weighted fits (the outliers of each dropped before the next).

    Returns
    -------
    GlobalMotion
        ``method`` ``"similarity"``; translation at the image centre, px; ``residual_rms``
        over the kept blocks, px; ``inliers`` the kept blocks (0, with zero motion and a NaN
        residual, when fewer than 3 blocks are usable).

    Raises
    ------
    ValueError
        ``iterations`` not an integer >= 1.
    """
    if isinstance(iterations, bool) or not isinstance(iterations, numbers.Integral) or iterations < 1:
        raise ValueError(f"iterations: expected an integer >= 1, got {iterations!r}")
    w, h = field.image_size
    c0 = ((w - 1) / 2.0, (h - 1) / 2.0)
    use = field.confidence >= min_confidence
    n_use = int(np.count_nonzero(use))
    if n_use < 3:
        return _no_motion(field, "similarity")
    x = np.empty((len(use), 5))  # rows [1, p, q]: p the block centre about the image centre, q = p + flow
    x[:, 0] = 1.0
    p = np.subtract(field.centers, c0, out=x[:, 1:3])
    np.add(p, field.vectors, out=x[:, 3:5])  # q
    wt = field.confidence * use
    keep, n_keep = use, n_use
    for _ in range(iterations):
        a, b, tx, ty = _similarity_from_gram((x * wt[:, None]).T @ x)
        res = x @ np.array([[tx, ty], [a, b], [-b, a], [-1.0, 0.0], [0.0, -1.0]])  # model - q
        r2 = np.vecdot(res, res)
        med2 = float(np.partition(r2[keep], n_keep // 2)[n_keep // 2])  # median of squares
        limit = 9.0 * max(1.4826**2 * med2, 0.01)  # (3 x spread)^2
        new = use & (r2 <= limit)
        n_new = int(np.count_nonzero(new))
        if n_new < 3 or n_new == n_keep and np.array_equal(new, keep):
            break
        keep, n_keep = new, n_new
        wt = wt * keep
    rms = math.sqrt(float(r2 @ keep) / n_keep)
    return GlobalMotion(np.array([tx, ty]), math.atan2(b, a), math.hypot(a, b), _rotation_centre(a, b, tx, ty, c0),
                        rms, n_keep, "similarity")


def _rotation_centre(a: float, b: float, tx: float, ty: float, c0: tuple[float, float]) -> NDArray | None:
    """Fixed point of the motion (in image coordinates), or None for a (near) pure
    translation, whose centre is at infinity."""
    am1 = a - 1.0  # solve [[a - 1, -b], [b, a - 1]] c = -t in closed form
    det = am1 * am1 + b * b
    if abs(math.atan2(b, a)) < _MIN_ROTATION or det < 1e-12:
        return None
    cx = (-am1 * tx - b * ty) / det
    cy = (b * tx - am1 * ty) / det
    if math.hypot(cx, cy) > _FAR * 2.0 * math.hypot(c0[0], c0[1]):
        return None
    return np.array([cx + c0[0], cy + c0[1]])


def instantaneous_rotation(field: FlowField, *, min_confidence: float = 0.2) -> GlobalMotion:
    """The report's solver (Appendix H): centre of instantaneous rotation and angle.

    For each row i of blocks, the x positions of its blocks and the y components of their
    flow lie on a line with its own slope ``a_i`` and a common zero crossing ``c_x``:
    ``x_ij = c_x + a_i dy_ij``, solved for all rows at once by least squares (eqs. H.1-H.2);
    ``c_y`` likewise from the columns with x and y swapped. That holds for small angles; a
    second pass removes the finite angle's ``(cos g - 1)`` term from the flow and solves again. The angle is the mean of every
    vector's rotation about that centre (H.3-H.6, with the perpendicular taken so that a
    rotation turning +x toward +y is positive). The translation at the image centre follows
    from rotating the centre about ``c`` (H.7, exactly rather than with ``tan``).

    When the flow has no rotation the two systems are singular (all lines parallel, the
    centre at infinity), or the rotation found explains the flow no better than a
    translation: then the result is the confidence-weighted mean translation, with
    ``center_of_rotation=None``.

    Parameters
    ----------
    field, min_confidence : as :func:`similarity_fit`

    Returns
    -------
    GlobalMotion
        ``method`` ``"cir"``; ``center_of_rotation`` in px (image coordinates) or None.
    """
    c0 = _image_center(field)
    use = field.confidence >= min_confidence
    if use.sum() < 3:
        return _no_motion(field, "cir")
    pts, vec, wt = field.centers[use], field.vectors[use], field.confidence[use]
    mean_t = (wt[:, None] * vec).sum(axis=0) / wt.sum()
    gamma, c = 0.0, None
    for _ in range(2):  # the second pass corrects the first's small-angle approximation
        # exact rotation: dy = sin g (x - cx) + (cos g - 1)(y - cy); dx = -sin g (y - cy) + (cos g - 1)(x - cx)
        k = np.cos(gamma) - 1.0
        fix_y = k * (pts[:, 1] - c[1]) if c is not None else 0.0
        fix_x = k * (pts[:, 0] - c[0]) if c is not None else 0.0
        cx = _common_zero_crossing(pts[:, 0], pts[:, 1], vec[:, 1] - fix_y, wt)  # rows: x vs dy
        cy = _common_zero_crossing(pts[:, 1], pts[:, 0], -(vec[:, 0] - fix_x), wt)  # columns: y vs -dx
        if cx is None or cy is None:
            return GlobalMotion(mean_t, 0.0, 1.0, None, _rms(vec - mean_t), int(use.sum()), "cir")
        c = np.array([cx, cy])
        r = pts - c
        cross = r[:, 0] * vec[:, 1] - r[:, 1] * vec[:, 0]  # report eq. (H.5), perpendicular fixed
        gamma_i = np.arctan2(cross, (r * r).sum(axis=1) + (r * vec).sum(axis=1))
        gamma = float((wt * gamma_i).sum() / wt.sum())  # report eq. (H.6), confidence-weighted
    cg, sg = np.cos(gamma), np.sin(gamma)
    rc = c0 - c
    t = np.array([cg * rc[0] - sg * rc[1], sg * rc[0] + cg * rc[1]]) - rc  # report eq. (H.7)
    model = np.stack([cg * r[:, 0] - sg * r[:, 1], sg * r[:, 0] + cg * r[:, 1]], axis=1) - r
    rms_rot, rms_trans = _rms(vec - model), _rms(vec - mean_t)
    if rms_rot >= rms_trans:  # the rotation explains nothing: a translation, centre at infinity
        return GlobalMotion(mean_t, 0.0, 1.0, None, rms_trans, int(use.sum()), "cir")
    return GlobalMotion(t, gamma, 1.0, c, rms_rot, int(use.sum()), "cir")


def _common_zero_crossing(pos: NDArray, group: NDArray, comp: NDArray, wt: NDArray) -> float | None:
    """Least squares of ``pos_ij = c + a_i comp_ij`` over groups i (report eqs. H.1-H.2);
    returns c, or None when the system is (nearly) singular."""
    keys, idx = np.unique(np.round(group, 3), return_inverse=True)
    n = len(keys)
    A = np.zeros((len(pos), n + 1))
    A[:, 0] = 1.0
    A[np.arange(len(pos)), 1 + idx] = comp
    sw = np.sqrt(wt)
    sol, _, rank, sv = np.linalg.lstsq(A * sw[:, None], pos * sw, rcond=None)
    if rank < n + 1 or sv[-1] < 1e-6 * sv[0]:
        return None
    spread = np.abs(comp).max() if len(comp) else 0.0
    if spread < 1e-3:  # no rotation signal in this component
        return None
    return float(sol[0])


def _rms(r: NDArray) -> float:
    return float(np.sqrt(np.mean((r * r).sum(axis=1)))) if len(r) else 0.0


def _no_motion(field: FlowField, method: str) -> GlobalMotion:
    return GlobalMotion(np.zeros(2), 0.0, 1.0, None, float("nan"), 0, method)


def global_motion(field: FlowField, *, method: str = "similarity", min_confidence: float = 0.2) -> GlobalMotion:
    """The image content's global motion from a :class:`FlowField`.

    Parameters
    ----------
    field : FlowField
    method : {"similarity", "cir"}
        ``"similarity"``: robust weighted least-squares rotation + scale + translation
        (default; see ``bench/flow.py``). ``"cir"``: the report's centre of instantaneous
        rotation (Appendix H).
    min_confidence : float
        Blocks below this confidence are not used.

    Returns
    -------
    GlobalMotion
        ``inliers == 0`` when fewer than three blocks were usable (then no motion).
    """
    if not isinstance(field, FlowField):
        raise TypeError(f"field must be a FlowField, got {type(field).__name__}")
    if method == "similarity":
        return similarity_fit(field, min_confidence=min_confidence)
    if method == "cir":
        return instantaneous_rotation(field, min_confidence=min_confidence)
    raise ValueError(f"method must be one of {METHODS}, got {method!r}")
