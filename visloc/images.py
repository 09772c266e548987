"""Input checking and grey conversion for images (stage 1 of the marker pipeline)."""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray


def check_image(image: object, name: str = "image") -> NDArray[np.uint8]:
    """Check that ``image`` is a usable uint8 grey or BGR image and return it as an array.

    Raises
    ------
    TypeError
        If ``image`` is not a numpy array or its dtype is not uint8.
    ValueError
        If its shape is not (H, W), (H, W, 1), (H, W, 3) or (H, W, 4), or it is smaller than
        2 x 2 pixels.
    """
    if not isinstance(image, np.ndarray):
        raise TypeError(f"{name} must be a numpy array, got {type(image).__name__}")
    if image.dtype != np.uint8:
        raise TypeError(f"{name} must have dtype uint8, got {image.dtype}")
    if image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] not in (1, 3, 4)):
        raise ValueError(f"{name} must have shape (H, W) or (H, W, 3), got {image.shape}")
    if image.shape[0] < 2 or image.shape[1] < 2:
        raise ValueError(f"{name} must be at least 2 x 2 pixels, got {image.shape}")
    return image


def as_gray(image: object, name: str = "image") -> NDArray[np.uint8]:
    """Return ``image`` as a contiguous ``(H, W)`` uint8 grey image.

    BGR (3 channels) and BGRA (4 channels) are converted with OpenCV's luma weights; a grey
    image is returned without a copy when it is already contiguous.
    """
    img = check_image(image, name)
    if img.ndim == 3:
        if img.shape[2] == 1:
            img = img[:, :, 0]
        elif img.shape[2] == 3:
            img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
        else:
            img = cv2.cvtColor(img, cv2.COLOR_BGRA2GRAY)
    return np.ascontiguousarray(img)
