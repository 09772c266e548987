"""Stages 1-3 of the marker pipeline: grey conversion, Gaussian blur, adaptive threshold.

Report Appendix G: "the original coloured image is transformed into a grey-scale image.
Secondly, to reduce noise in the image a small scale Gaussian blur filter is applied and the
image is by thresholding transformed into a binary image" (Figure G.1.B).
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from visloc.images import as_gray

__all__ = ["blur", "default_window", "threshold", "to_gray"]


def to_gray(image: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """Stage 1: a uint8 grey or BGR image as a contiguous ``(H, W)`` uint8 grey image."""
    return as_gray(image, "image")


def blur(gray: NDArray[np.uint8], sigma: float = 0.6) -> NDArray[np.uint8]:
    """Stage 2: Gaussian blur with standard deviation ``sigma`` px (0 returns ``gray``); the
    default is the detector's (``DetectorParams.blur_sigma``).

    The kernel is ``2 * ceil(2.5 sigma) + 1`` wide, so ``sigma=0.6`` gives a 5x5 kernel.
    """
    if sigma < 0:
        raise ValueError(f"sigma must be >= 0, got {sigma}")
    if sigma == 0:
        return gray
    k = 2 * int(np.ceil(2.5 * sigma)) + 1
    return cv2.GaussianBlur(gray, (k, k), sigma, borderType=cv2.BORDER_REPLICATE)


def default_window(shape: tuple[int, ...]) -> int:
    """Adaptive-threshold window for an image of ``shape``: about 1/40 of the short side, odd, >= 7."""
    w = max(7, round(min(shape[:2]) / 40.0))
    return w | 1


def threshold(gray: NDArray[np.uint8], *, window: int = 9, offset: float = 7.0) -> NDArray[np.uint8]:
    """Stage 3: adaptive local-mean threshold; 255 marks *dark* (ink) pixels.

    A pixel is ink when it is darker than the mean of its ``window x window`` neighbourhood
    by more than ``offset`` grey levels. The marker's black border then forms a closed ink
    ring whose outer border the contour follower traces.

    Parameters
    ----------
    gray : ndarray (H, W) uint8
    window : int
        Odd neighbourhood size in pixels, >= 3 (default: the detector's first search pass).
    offset : float
        How much darker than the local mean a pixel must be, grey levels (default: the
        detector's ``DetectorParams.offset``).
    """
    if window < 3 or window % 2 == 0:
        raise ValueError(f"window must be an odd integer >= 3, got {window}")
    return cv2.adaptiveThreshold(
        gray, 255, cv2.ADAPTIVE_THRESH_MEAN_C, cv2.THRESH_BINARY_INV, int(window), float(offset)
    )
