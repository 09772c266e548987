"""The camera's response: how an 8-bit grey level relates to the light that reached the pixel.

Stage 8 (:mod:`visloc.markers.refine`) finds an edge from the area of the intensity step
across it. That area is only unbiased in *linear* intensity: optics blur mixes light, not
encoded grey levels. Almost every camera writes 8-bit images through the sRGB transfer curve
(about gamma 2.2), and a blurred black/white edge then crosses mid-grey on the bright side of
the true edge: fitted in encoded values, every outer side of a marker moves outward by a
fraction of the blur width (0.7 px RMS on 640 x 480 renders with sigma 0.3-0.8 px blur).

A response is a look-up table of 256 linear intensities (on a 0-255 scale), one per grey
level; the refinement samples the image through it. ``"srgb"`` (the default of
:class:`~visloc.markers.MarkerDetector`) inverts the sRGB curve (IEC 61966-2-1),
``"linear"`` is the identity for linear sensors and linear renders, and a number ``g`` is a
pure power law ``255 (v / 255) ** g``.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

__all__ = ["RESPONSES", "response_lut", "srgb_to_linear"]

#: Named responses accepted by :func:`response_lut`.
RESPONSES = ("srgb", "linear")


def srgb_to_linear(v: NDArray | float) -> NDArray[np.float64]:
    """The sRGB decoding curve: ``v / 12.92`` up to 0.04045, else ``((v + 0.055) / 1.055) ** 2.4``.

    Parameters
    ----------
    v : float or ndarray, any shape
        sRGB-encoded values on a 0-1 scale (not clipped).

    Returns
    -------
    ndarray float64, the shape of ``v``
        Linear light on a 0-1 scale (a 0-d array for a scalar ``v``).
    """
    v = np.asarray(v, np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


@lru_cache(maxsize=8)
def _lut(response: str | float) -> NDArray[np.float64]:
    v = np.arange(256, dtype=np.float64)
    if response == "linear":
        lut = v
    elif response == "srgb":
        lut = 255.0 * srgb_to_linear(v / 255.0)
    else:
        lut = 255.0 * (v / 255.0) ** float(response)
    lut.setflags(write=False)
    return lut


def response_lut(response: str | float | NDArray) -> NDArray[np.float64]:
    """Linear intensity (0-255 scale) of each 8-bit grey level.

    Parameters
    ----------
    response : {"srgb", "linear"}, float or ndarray (256,)
        The camera's transfer curve: ``"srgb"`` for images as cameras and most files store
        them, ``"linear"`` for linear sensor data and linear renders, a gamma ``g`` in
        (0, 10) (grey level ``v`` holds light ``255 (v / 255) ** g``), or the table itself
        (256 strictly increasing values).

    Returns
    -------
    ndarray (256,) float64
        Entry ``v``: the light of grey level ``v`` on a 0-255 scale. Read-only (cached) for a
        name or a gamma; a given table is returned as float64 (itself when it already is).

    Raises
    ------
    ValueError
        An unknown name, a gamma outside (0, 10) (or not a number), or a table that is not
        256 strictly increasing values.
    """
    if isinstance(response, np.ndarray):
        lut = np.asarray(response, np.float64)
        if lut.shape != (256,) or not np.all(np.diff(lut) > 0):
            raise ValueError(f"response: a table must be 256 increasing values, got shape {lut.shape}")
        return lut
    if isinstance(response, str):
        if response not in RESPONSES:
            raise ValueError(f"response must be one of {RESPONSES} or a gamma > 0, got {response!r}")
        return _lut(response)
    if isinstance(response, bool) or not isinstance(response, (int, float)) or not 0 < response < 10:
        raise ValueError(f"response must be one of {RESPONSES} or a gamma in (0, 10), got {response!r}")
    return _lut(float(response))
