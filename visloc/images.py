"""Input checking and grey conversion for images (stage 1 of the marker pipeline)."""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

#: sensor bit depths whose data 16-bit images and files commonly hold
_DEPTHS = (8, 10, 12, 14, 16)


def _depth(top: float) -> int:
    """The smallest common bit depth that holds the value ``top``."""
    return next((d for d in _DEPTHS if top < (1 << d)), 16)


def to_uint8(image: NDArray) -> NDArray[np.uint8]:
    """Pixel values of any depth as uint8 (the same shape).

    uint16 keeps the top 8 bits of the bit depth its values fit in (8, 10, 12, 14 or 16 bits;
    for 16 bits that is ``cv2.imread``'s ``>> 8``), so 12-bit sensor data in a 16-bit file
    spans 0..255 like 16-bit data instead of reading nearly black. Floating point is taken as
    0..1 when its largest value is at most 1, as 0..255 when at most 255, else scaled like
    uint16; NaN and infinities read as 0; values are rounded and clipped.

    Parameters
    ----------
    image : ndarray, any shape, uint8, uint16 or floating point
        Pixel values (grey or multi-channel alike: every value is converted on its own).

    Returns
    -------
    ndarray, the shape of ``image``, uint8
        Grey levels 0-255; ``image`` itself when it is already uint8.

    Raises
    ------
    TypeError
        For other pixel types (signed integers, booleans, ...).
    """
    if image.dtype == np.uint8:
        return image
    if image.dtype == np.uint16:
        top = int(image.max()) if image.size else 0
        return (image >> (_depth(top) - 8)).astype(np.uint8)
    if np.issubdtype(image.dtype, np.floating):
        v = np.nan_to_num(image.astype(np.float64, copy=False), nan=0.0, posinf=0.0, neginf=0.0)
        top = float(v.max()) if v.size else 0.0
        scale = 255.0 if top <= 1.0 else (1.0 if top <= 255.0 else 1.0 / (1 << (_depth(top) - 8)))
        return np.clip(v * scale + 0.5, 0, 255).astype(np.uint8)
    raise TypeError(f"unsupported pixel type {image.dtype}: expected uint8, uint16 or floating point")


def check_image(image: object, *, name: str = "image") -> NDArray[np.uint8]:
    """Check that ``image`` is a usable grey or BGR image and return it as a uint8 array.

    Parameters
    ----------
    image : ndarray (H, W), (H, W, 1), (H, W, 3) or (H, W, 4); uint8, uint16 or floating point
        Grey, BGR or BGRA pixels, at least 2 x 2; uint16 and floating-point values are
        converted by :func:`to_uint8`.
    name : str
        Name of the argument in error messages.

    Returns
    -------
    ndarray, the shape of ``image``, uint8
        ``image`` itself when it is uint8 (no copy, channels unchanged), else its conversion.

    Raises
    ------
    TypeError
        If ``image`` is not a numpy array or its pixel type is not uint8, uint16 or floating point.
    ValueError
        If its shape is not (H, W), (H, W, 1), (H, W, 3) or (H, W, 4), it is smaller than
        2 x 2 pixels, or it has NaN or infinite pixels.
    """
    if not isinstance(image, np.ndarray):
        raise TypeError(f"{name} must be a numpy array, got {type(image).__name__}")
    if np.issubdtype(image.dtype, np.floating) and not np.isfinite(image).all():
        raise ValueError(f"{name} has NaN or infinite pixels")
    if image.dtype != np.uint8:
        try:
            image = to_uint8(image)
        except TypeError:
            raise TypeError(f"{name} must have dtype uint8 (or uint16, floating point), got {image.dtype}") from None
    if image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] not in (1, 3, 4)):
        raise ValueError(f"{name} must have shape (H, W) or (H, W, 3), got {image.shape}")
    if image.shape[0] < 2 or image.shape[1] < 2:
        raise ValueError(f"{name} must be at least 2 x 2 pixels, got {image.shape}")
    return image


def as_gray(image: object, *, name: str = "image") -> NDArray[np.uint8]:
    """Return ``image`` as a contiguous grey image.

    BGR (3 channels) and BGRA (4 channels) are converted with OpenCV's luma weights; a grey
    image is returned without a copy when it is already contiguous.

    Parameters
    ----------
    image : ndarray (H, W), (H, W, 1), (H, W, 3) or (H, W, 4); uint8, uint16 or floating point
        Grey, BGR or BGRA pixels, as :func:`check_image` accepts them.
    name : str
        Name of the argument in error messages.

    Returns
    -------
    ndarray (H, W) uint8, C-contiguous
        The grey image.

    Raises
    ------
    TypeError, ValueError
        As :func:`check_image`: not a numpy array, an unsupported pixel type or shape, smaller
        than 2 x 2 pixels, or NaN / infinite pixels.
    """
    img = check_image(image, name=name)
    if img.ndim == 3:
        if img.shape[2] == 1:
            img = img[:, :, 0]
        elif img.shape[2] == 3:
            img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
        else:
            img = cv2.cvtColor(img, cv2.COLOR_BGRA2GRAY)
    return np.ascontiguousarray(img)
