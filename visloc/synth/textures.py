"""Backgrounds and image degradations for the synthetic renderers.

Backgrounds are float64 ``(H, W)`` arrays of grey levels. Degradations act on such float
images in the order the renderers apply them: optical blur, motion blur, illumination
(gradient and gain), sensor noise, then quantisation to uint8 and an optional JPEG round trip.
Blur kernels are symmetric about their centre, so they move no edge: the ground truth of a
blurred render is the ground truth of the sharp one.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from visloc.images import as_gray

FloatArray = NDArray[np.float64]

#: Names accepted as ``background`` by the renderers.
TEXTURES = ("grass", "gravel", "brick", "noise", "flat")


@lru_cache(maxsize=4)
def _photo_texture(name: str) -> NDArray[np.uint8]:
    """One of the CC0 ground photographs shipped in ``visloc/synth/data`` (see its README)."""
    path = Path(__file__).with_name("data") / f"{name}.png"
    img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise ValueError(f"background {name!r}: texture file {path} is missing or unreadable")
    img.setflags(write=False)
    return img


def smooth_noise(shape: tuple[int, int], rng: np.random.Generator) -> FloatArray:
    """A smooth random texture: octaves of upsampled Gaussian noise, mean 128, std ~40.

    Parameters
    ----------
    shape : (int, int)
        ``(height, width)``.
    rng : numpy.random.Generator
        Source of randomness.

    Returns
    -------
    ndarray (height, width) float64
        Grey levels in [0, 255].
    """
    h, w = shape
    out = np.zeros((h, w))
    for cell, amp in ((48, 1.0), (16, 0.6), (5, 0.35), (2, 0.2)):
        coarse = rng.normal(size=(max(h // cell, 1) + 3, max(w // cell, 1) + 3))
        big = cv2.resize(coarse, (w + 3 * cell, h + 3 * cell), interpolation=cv2.INTER_CUBIC)
        out += amp * big[cell : cell + h, cell : cell + w]
    out = (out - out.mean()) / max(float(out.std()), 1e-12)
    return np.clip(128.0 + 40.0 * out, 0.0, 255.0)


def make_background(
    background: str | NDArray | None, size: tuple[int, int], rng: np.random.Generator
) -> tuple[FloatArray, str]:
    """Build a background image for a render.

    Parameters
    ----------
    background : str, ndarray (H, W) uint8 or None
        A name from :data:`TEXTURES` or an image of the render's size; ``None`` = ``'flat'``.
        Named photographic textures (``grass``, ``gravel``, ``brick``: CC0 photographs from
        scikit-image's data set, shipped in ``visloc/synth/data``) are mirror-tiled to cover
        the image from a random offset.
    size : (int, int)
        ``(width, height)`` of the render.
    rng : numpy.random.Generator
        Source of the random offset and of the ``'noise'`` texture.

    Returns
    -------
    image : ndarray (H, W) float64
        Grey levels.
    name : str
        The texture name, or ``'array'`` for a given image.

    Raises
    ------
    TypeError
        If ``background`` is not None, a str or a numpy array, or its pixel type is not
        supported (:func:`visloc.images.as_gray`).
    ValueError
        An unknown name, an image of another size or shape, or a missing texture file.
    """
    w, h = size
    if background is None:
        background = "flat"
    if isinstance(background, np.ndarray):
        img = as_gray(background, name="background")
        if img.shape != (h, w):
            raise ValueError(f"background must have shape {(h, w)} (H, W), got {img.shape}")
        return img.astype(np.float64), "array"
    if not isinstance(background, str):
        raise TypeError(
            f"background must be None, a texture name or a uint8 array, got {type(background).__name__}"
        )
    if background not in TEXTURES:
        raise ValueError(f"background must be one of {TEXTURES} or an array, got {background!r}")
    if background == "flat":
        return np.full((h, w), 128.0), background
    if background == "noise":
        return smooth_noise((h, w), rng), background
    tex = _photo_texture(background)
    th, tw = tex.shape
    oy, ox = int(rng.integers(0, th)), int(rng.integers(0, tw))
    reps = ((oy + h) // th + 1, (ox + w) // tw + 1)
    tiled = np.pad(tex, ((0, (reps[0] - 1) * th), (0, (reps[1] - 1) * tw)), mode="symmetric")
    return tiled[oy : oy + h, ox : ox + w].astype(np.float64), background


def motion_kernel(length: float, angle: float) -> NDArray[np.float32]:
    """Normalised kernel of a linear motion blur, symmetric about its centre.

    Parameters
    ----------
    length : float
        Length of the motion in pixels (> 0).
    angle : float
        Direction of the motion in the image, radians from the x axis towards y (down).

    Returns
    -------
    ndarray (k, k) float32
        Kernel summing to 1: a line segment of ``length`` through the centre, anti-aliased.
    """
    half = int(np.ceil(length / 2.0)) + 1
    k = np.zeros((2 * half + 1, 2 * half + 1))
    s = np.linspace(-length / 2.0, length / 2.0, max(int(np.ceil(8 * length)), 16))
    x = half + s * np.cos(angle)
    y = half + s * np.sin(angle)
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    for dx, dy, wgt in ((0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)),
                        (0, 1, (1 - fx) * fy), (1, 1, fx * fy)):
        np.add.at(k, (y0 + dy, x0 + dx), wgt)
    k = 0.5 * (k + k[::-1, ::-1])  # exact point symmetry: the blur moves no edge
    return (k / k.sum()).astype(np.float32)


def degrade(
    image: FloatArray,
    rng: np.random.Generator,
    *,
    blur_sigma: float = 0.0,
    motion_blur: float = 0.0,
    motion_angle: float = 0.0,
    gradient: float = 0.0,
    gain: float = 1.0,
    noise_sigma: float = 0.0,
    jpeg_quality: int | None = None,
    fast_noise: bool = False,
) -> tuple[NDArray[np.uint8], float | None]:
    """Apply the camera degradations to a float image and quantise it to uint8.

    Order: Gaussian optical blur, linear motion blur, multiplicative illumination gradient
    ``1 - gradient * s`` (``s`` from 0 to 1 across the image along a random direction) and
    ``gain``, additive Gaussian noise, rounding and clipping to uint8, JPEG round trip.
    Arguments are assumed valid (the public renderers check them).

    Parameters
    ----------
    image : ndarray (H, W) float
        Grey levels on a 0-255 scale (clipped when quantised).
    rng : numpy.random.Generator
        Source of the gradient direction and of the noise.
    blur_sigma : float
        Standard deviation of the Gaussian optical blur, px (0: none); the image's border is
        mirrored.
    motion_blur : float
        Length of the linear motion blur, px (0: none).
    motion_angle : float
        Direction of the motion blur, radians from image x towards y (down).
    gradient : float
        Strength of the illumination gradient, in [0, 1) (0: none).
    gain : float
        Exposure factor (> 0).
    noise_sigma : float
        Standard deviation of the additive Gaussian noise, grey levels (0: none).
    jpeg_quality : int or None
        JPEG round-trip quality in [1, 100], or ``None`` for none.
    fast_noise : bool
        Draw the noise with OpenCV's ``cv2.randn`` (its per-thread generator seeded from
        ``rng``) in a sixth of ``rng.normal``'s time, and do the arithmetic in float32 (the
        same rounding to uint8). False keeps float64 and ``rng.normal``, with which every
        stored render was made.

    Returns
    -------
    image : ndarray (H, W) uint8
        The degraded image.
    gradient_angle : float or None
        Direction (radians, x towards y) in which the illumination falls off, if any.
    """
    img = _blur(image.astype(np.float32), blur_sigma, motion_blur, motion_angle)
    if not fast_noise:
        img = img.astype(np.float64)  # the stored renders' arithmetic
    angle = None
    if gradient > 0:
        angle = float(rng.uniform(0.0, 2.0 * np.pi))
        img *= _illumination_ramp(img.shape, angle, gradient)
    if gain != 1.0:
        img *= gain
    out = _add_noise_and_quantise(img, rng, noise_sigma, fast_noise)
    if jpeg_quality is not None:
        out = _jpeg_round_trip(out, jpeg_quality)
    return out, angle


def _blur(img: NDArray[np.float32], blur_sigma: float, motion_blur: float,
          motion_angle: float) -> NDArray[np.float32]:
    """Gaussian optical blur (sigma, px) then linear motion blur (length, px; angle, rad) of a
    float32 image, borders mirrored; a zero sigma or length skips that blur."""
    if blur_sigma > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur_sigma, borderType=cv2.BORDER_REFLECT)
    if motion_blur > 0:
        img = cv2.filter2D(img, -1, motion_kernel(motion_blur, motion_angle),
                           borderType=cv2.BORDER_REFLECT)
    return img


def _illumination_ramp(shape: tuple[int, int], angle: float, gradient: float) -> FloatArray:
    """Illumination factor (H, W): 1 falling linearly to ``1 - gradient`` across the image
    along direction ``angle`` (rad, x towards y)."""
    h, w = shape
    ys, xs = np.mgrid[0:h, 0:w]
    proj = xs * np.cos(angle) + ys * np.sin(angle)
    span = max(float(proj.max() - proj.min()), 1e-12)
    return 1.0 - gradient * (proj - proj.min()) / span


def _add_noise_and_quantise(img: NDArray, rng: np.random.Generator, noise_sigma: float,
                            fast_noise: bool) -> NDArray[np.uint8]:
    """Add Gaussian noise (sigma in grey levels; 0: none) to ``img``, round (half to even) and
    clip to uint8; see :func:`degrade`'s ``fast_noise``. ``img`` is float32 with
    ``fast_noise``, else float64 and overwritten."""
    if fast_noise:  # float32 throughout; OpenCV's generator seeded from rng, one rounding add
        noise = np.zeros(img.shape, np.float32)
        if noise_sigma > 0:
            cv2.setRNGSeed(int(rng.integers(1 << 31)))
            cv2.randn(noise, 0.0, float(noise_sigma))
        return cv2.add(img, noise, dtype=cv2.CV_8U)  # rounded half to even and clipped, as below
    if noise_sigma > 0:
        img += rng.normal(0.0, noise_sigma, img.shape)
    np.rint(img, out=img)  # in place: a new array from np.clip costs 8x as much at 320 x 240
    np.clip(img, 0, 255, out=img)
    return img.astype(np.uint8)


def _jpeg_round_trip(image: NDArray[np.uint8], quality: int) -> NDArray[np.uint8]:
    """Encode a grey uint8 image as JPEG at ``quality`` (1-100) and decode it again."""
    ok, buf = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:  # pragma: no cover - OpenCV always encodes a valid grey image
        raise RuntimeError("JPEG encoding failed")
    return cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE)
