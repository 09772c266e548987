"""Stages 1-3 of the marker pipeline: grey conversion, Gaussian blur, adaptive threshold.

Report Appendix G: "the original coloured image is transformed into a grey-scale image.
Secondly, to reduce noise in the image a small scale Gaussian blur filter is applied and the
image is by thresholding transformed into a binary image" (Figure G.1.B).
"""

from __future__ import annotations

import math

import cv2
import numpy as np
from numpy.typing import NDArray

from visloc._compiled import use_compiled
from visloc.images import as_gray

try:  # stage 3 compiled (visloc/markers/_threshold.c): the same binary image, about twice as fast
    from visloc.markers import _threshold
except ImportError:  # pragma: no cover - built without a C compiler
    _threshold = None

__all__ = ["blur", "default_window", "threshold", "to_gray"]


def to_gray(image: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """Stage 1: the image as a grey image (:func:`visloc.images.as_gray`).

    Parameters
    ----------
    image : ndarray (H, W) or (H, W, 3) uint8
        Grey or BGR image ((H, W, 1), BGRA (H, W, 4), uint16 and floating point are accepted
        and converted as :func:`visloc.images.as_gray` does).

    Returns
    -------
    ndarray (H, W) uint8, C-contiguous
        The grey image (``image`` itself when it is already contiguous grey uint8).

    Raises
    ------
    TypeError, ValueError
        If ``image`` is not a usable image (:func:`visloc.images.check_image`).
    """
    return as_gray(image, name="image")


def blur(gray: NDArray[np.uint8], *, sigma: float = 0.6) -> NDArray[np.uint8]:
    """Stage 2: Gaussian blur, the image's edge pixels repeated beyond it.

    The kernel is ``2 * ceil(2.5 sigma) + 1`` wide, so ``sigma=0.6`` gives a 5x5 kernel.

    Parameters
    ----------
    gray : ndarray (H, W) uint8
        Grey image.
    sigma : float
        Standard deviation of the Gaussian, px, >= 0 (default: the detector's
        ``DetectorParams.blur_sigma``); 0 returns ``gray`` itself.

    Returns
    -------
    ndarray (H, W) uint8
        The blurred image (``gray`` itself when ``sigma`` is 0).

    Raises
    ------
    ValueError
        If ``sigma`` is negative.
    """
    if sigma < 0:
        raise ValueError(f"sigma must be >= 0, got {sigma}")
    if sigma == 0:
        return gray
    k = 2 * int(np.ceil(2.5 * sigma)) + 1
    return cv2.GaussianBlur(gray, (k, k), sigma, borderType=cv2.BORDER_REPLICATE)


def default_window(shape: tuple[int, ...]) -> int:
    """Adaptive-threshold window for an image of ``shape``.

    Parameters
    ----------
    shape : tuple of int
        The image's shape ``(H, W)`` or ``(H, W, C)``; only ``H`` and ``W`` are used.

    Returns
    -------
    int
        Window side, px: about 1/40 of the short side, odd, >= 7.
    """
    w = max(7, round(min(shape[:2]) / 40.0))
    return w | 1


def threshold(gray: NDArray[np.uint8], *, window: int = 9, offset: float = 7.0,
              native: bool | None = None) -> NDArray[np.uint8]:
    """Stage 3: adaptive local-mean threshold; 255 marks *dark* (ink) pixels.

    A pixel is ink when it is darker than the mean of its ``window x window`` neighbourhood
    by more than ``offset`` grey levels. The marker's black border then forms a closed ink
    ring whose outer border the contour follower traces.

    Parameters
    ----------
    gray : ndarray (H, W) uint8
        Grey image, usually blurred (:func:`blur`).
    window : int
        Odd neighbourhood size in pixels, >= 3 (default: the detector's first search pass).
        The image's edge pixels are repeated beyond it.
    offset : float
        How much darker than the local mean a pixel must be, grey levels (default: the
        detector's ``DetectorParams.offset``). As OpenCV's, the test is
        ``gray - round(mean) <= -floor(offset)``.
    native : bool or None
        Run the compiled threshold (``visloc.markers._threshold``, pixel for pixel
        ``cv2.adaptiveThreshold(gray, 255, ADAPTIVE_THRESH_MEAN_C, THRESH_BINARY_INV, window,
        offset)``): ``None`` when it was built (and ``window <= 255``, ``|offset| <= 1024``),
        ``False`` never (OpenCV's), ``True`` always.

    Returns
    -------
    ndarray (H, W) uint8
        Binary image: 255 on ink (dark) pixels, 0 elsewhere.

    Raises
    ------
    TypeError
        If ``gray`` is not a numpy array.
    ValueError
        If ``gray`` is not a non-empty (H, W) uint8 image (both ways: the compiled threshold
        used to cast other types silently, wrapping 300 to 44 and -1 to 255), ``window`` not
        an odd integer >= 3 (or, compiled, above 255) or ``offset`` not finite.
    RuntimeError
        If ``native=True`` and the compiled module was not built.
    """
    if not isinstance(gray, np.ndarray):
        raise TypeError(f"gray: expected a numpy array, got {type(gray).__name__}")
    if gray.dtype != np.uint8 or gray.ndim != 2 or not gray.size:
        raise ValueError(f"gray must be a non-empty (H, W) uint8 image, got shape {gray.shape} {gray.dtype}")
    if isinstance(window, bool) or not isinstance(window, (int, np.integer)) or window < 3 or window % 2 == 0:
        raise ValueError(f"window must be an odd integer >= 3, got {window!r}")
    if not math.isfinite(offset):
        raise ValueError(f"offset must be a finite number, got {offset!r}")
    idelta = int(np.floor(offset))
    if native is None and (window > 255 or abs(idelta) > 1024):
        native = False  # beyond the compiled loop's integer ranges
    if use_compiled(native, _threshold, "visloc.markers._threshold"):
        g = np.ascontiguousarray(gray)
        out = np.empty_like(g)
        _threshold.mean_threshold(g, out, g.shape[0], g.shape[1], int(window), idelta)
        return out
    return cv2.adaptiveThreshold(
        gray, 255, cv2.ADAPTIVE_THRESH_MEAN_C, cv2.THRESH_BINARY_INV, int(window), float(offset)
    )
