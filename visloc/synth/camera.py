"""A camera model for the synthetic renderers: from ideal scene radiance to an 8-bit frame.

The renderers compute an *ideal* image: the pixel-area integral of the scene radiance seen by
a pinhole camera ``K``, in linear light (0..255, 255 = white paper at exposure 1).
:func:`apply_camera` turns it into what a camera writes, in the order light meets them:

1. radial lens distortion (OpenCV model, coefficients ``k1``, ``k2`` on normalised
   coordinates ``K^-1 p``): output pixel ``p_d`` shows the ideal image at ``p_u`` with
   ``distort(p_u) = p_d``, sampled bilinearly;
2. optical blur (Gaussian PSF) and linear motion blur, both symmetric (they move no edge);
3. vignetting, a cos^4-like radial falloff of the illumination;
4. exposure gain;
5. sensor noise: photon shot noise (variance proportional to the signal, from the full-well
   capacity) and read noise, then clipping to the sensor's range;
6. the sRGB transfer curve, 8-bit quantisation and an optional JPEG round trip.

The ground truth of a distorted render is :func:`distort_points` of its pinhole projections;
the image pairs with the OpenCV camera ``K``, ``(k1, k2, 0, 0, 0)``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from functools import lru_cache

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from visloc._checks import check_int
from visloc.markers.response import srgb_to_linear
from visloc.synth._checks import check_camera, check_number, check_rng, check_size
from visloc.synth.textures import _blur, _jpeg_round_trip

FloatArray = NDArray[np.float64]

#: Largest residual of the undistorted radii (normalised units; ~1e-7 px).
_TOL = 1e-10


@dataclass(frozen=True, kw_only=True)
class CameraEffects:
    """What a camera does to the ideal image; the defaults give a typical webcam.

    Attributes
    ----------
    blur_sigma : float
        Optical blur: standard deviation of the Gaussian PSF in pixels (>= 0).
    full_well : float or None
        Photo-electrons collected at linear grey level 255: shot noise has variance
        ``255 * s / full_well`` grey levels squared at signal ``s`` (> 0); ``None`` for none.
    read_noise : float
        Standard deviation of the read noise in linear grey levels (>= 0).
    vignetting : float
        Fraction of the light lost at the image corner farthest from the principal point, in
        [0, 1): illumination ``1 / (1 + a rho^2)^2`` (cos^4 law) with ``rho`` the distance to
        the principal point over that corner's.
    k1, k2 : float
        Radial distortion coefficients (OpenCV model, normalised coordinates of ``K``);
        negative ``k1`` is barrel distortion.
    motion_blur : float
        Length of a linear motion blur in pixels (>= 0).
    motion_angle : float
        Direction of the motion blur, radians from x towards y.
    exposure : float
        Exposure gain (> 0) on the linear signal; below 1 simulates dim light.
    srgb : bool
        Encode with the sRGB transfer curve (``True``) or write linear values.
    jpeg_quality : int or None
        JPEG round-trip quality in [1, 100], or ``None`` for a lossless frame.
    """

    blur_sigma: float = 0.7
    full_well: float | None = 5000.0
    read_noise: float = 1.0
    vignetting: float = 0.2
    k1: float = -0.05
    k2: float = 0.0
    motion_blur: float = 0.0
    motion_angle: float = 0.0
    exposure: float = 1.0
    srgb: bool = True
    jpeg_quality: int | None = 90

    def __post_init__(self) -> None:
        def put(name: str, value: object) -> None:
            object.__setattr__(self, name, value)

        n = "CameraEffects."
        put("blur_sigma", check_number(self.blur_sigma, n + "blur_sigma", low=0.0, high=100.0))
        if self.full_well is not None:
            put("full_well", check_number(self.full_well, n + "full_well", low=0.0, low_open=True))
        put("read_noise", check_number(self.read_noise, n + "read_noise", low=0.0))
        put("vignetting", check_number(self.vignetting, n + "vignetting", low=0.0, high=1.0,
                                       high_open=True))
        put("k1", check_number(self.k1, n + "k1", low=-1.0, high=1.0))
        put("k2", check_number(self.k2, n + "k2", low=-1.0, high=1.0))
        put("motion_blur", check_number(self.motion_blur, n + "motion_blur", low=0.0, high=100.0))
        put("motion_angle", check_number(self.motion_angle, n + "motion_angle"))
        put("exposure", check_number(self.exposure, n + "exposure", low=0.0, low_open=True))
        if not isinstance(self.srgb, (bool, np.bool_)):
            raise TypeError(f"{n}srgb must be a bool, got {type(self.srgb).__name__}")
        put("srgb", bool(self.srgb))
        if self.jpeg_quality is not None:
            put("jpeg_quality", check_int(self.jpeg_quality, n + "jpeg_quality", low=1, high=100))

    @property
    def dist(self) -> FloatArray:
        """OpenCV distortion coefficients ``(5,)``: ``k1, k2, p1, p2, k3 = k1, k2, 0, 0, 0``."""
        return np.array([self.k1, self.k2, 0.0, 0.0, 0.0])

    def to_dict(self) -> dict:
        """The fields as a JSON-ready dict."""
        return asdict(self)


def srgb_encode(v: ArrayLike) -> FloatArray:
    """sRGB transfer curve (IEC 61966-2-1): linear light to encoded values.

    Parameters
    ----------
    v : array_like
        Linear values in [0, 1] (values outside are clipped).

    Returns
    -------
    ndarray float64
        ``12.92 v`` for ``v <= 0.0031308``, else ``1.055 v^(1/2.4) - 0.055``.
    """
    v = np.clip(np.asarray(v, dtype=np.float64), 0.0, 1.0)
    return np.where(v <= 0.0031308, 12.92 * v, 1.055 * np.power(v, 1.0 / 2.4) - 0.055)


def srgb_decode(v: ArrayLike) -> FloatArray:
    """Inverse of :func:`srgb_encode`: encoded values to linear light.

    Parameters
    ----------
    v : array_like
        Encoded values in [0, 1] (values outside are clipped).

    Returns
    -------
    ndarray float64
        ``v / 12.92`` for ``v <= 0.04045``, else ``((v + 0.055) / 1.055)^2.4``.
    """
    return srgb_to_linear(np.clip(np.asarray(v, dtype=np.float64), 0.0, 1.0))


def _normalise(points: FloatArray, K: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Normalised coordinates ``K^-1 [u, v, 1]`` of pixel points (N, 2)."""
    y = (points[:, 1] - K[1, 2]) / K[1, 1]
    x = (points[:, 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
    return x, y


def _to_pixels(x: FloatArray, y: FloatArray, K: FloatArray) -> FloatArray:
    """Pixel points (N, 2) ``K [x, y, 1]`` of normalised coordinates."""
    return np.stack([K[0, 0] * x + K[0, 1] * y + K[0, 2], K[1, 1] * y + K[1, 2]], axis=-1)


def distort_points(points: ArrayLike, K: ArrayLike, k1: float, k2: float) -> FloatArray:
    """Apply radial lens distortion to ideal (pinhole) pixel points.

    Parameters
    ----------
    points : array_like (N, 2)
        Pinhole image points ``(x, y)``, px, pixel centres at integer coordinates; non-finite
        points give non-finite results.
    K : array_like (3, 3)
        Camera matrix: defines the normalised coordinates ``K^-1 p`` the model acts on.
    k1, k2 : float
        Radial coefficients: ``x_d = x (1 + k1 r^2 + k2 r^4)`` in normalised coordinates,
        as :func:`cv2.projectPoints` with ``distCoeffs = (k1, k2, 0, 0, 0)`` (which assumes
        zero skew).

    Returns
    -------
    ndarray (N, 2) float64
        Distorted pixel points ``(x, y)``, px, same convention.

    Raises
    ------
    TypeError, ValueError
        On a malformed argument (``points`` not (N, 2) numbers, a bad ``K``, non-finite
        coefficients); the message names it.
    """
    k = check_camera(K)
    k1 = check_number(k1, "k1")
    k2 = check_number(k2, "k2")
    try:
        pts = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(
            f"points must be an (N, 2) array of numbers, got {type(points).__name__}"
        ) from exc
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"points must have shape (N, 2), got {pts.shape}")
    x, y = _normalise(pts, k)
    r2 = x * x + y * y
    f = 1.0 + r2 * (k1 + k2 * r2)
    return _to_pixels(x * f, y * f, k)


def monotonic_radius(k1: float, k2: float) -> float:
    """Largest normalised radius up to which the radial distortion is one-to-one.

    Parameters
    ----------
    k1, k2 : float
        Radial distortion coefficients.

    Returns
    -------
    float
        The first radius where ``d/dr [r (1 + k1 r^2 + k2 r^4)]`` vanishes, or ``inf``.
        Beyond it the distortion folds the image back on itself: points there are not seen
        where :func:`distort_points` puts them.
    """
    # d/dr [r (1 + k1 r^2 + k2 r^4)] = 1 + 3 k1 s + 5 k2 s^2 with s = r^2; first root s > 0
    roots = np.roots([5.0 * k2, 3.0 * k1, 1.0]) if (k1 or k2) else np.zeros(0)
    s = [float(r.real) for r in np.atleast_1d(roots) if abs(r.imag) < 1e-12 and r.real > 0]
    return float(np.sqrt(min(s))) if s else float("inf")


def _radial(r: FloatArray, k1: float, k2: float) -> FloatArray:
    """Distorted normalised radius ``r (1 + k1 r^2 + k2 r^4)``."""
    s = r * r
    return r * (1.0 + s * (k1 + k2 * s))


def _undistort_radius(rd: FloatArray, k1: float, k2: float) -> FloatArray:
    """Ideal radii ``r`` with ``_radial(r) = rd`` on the one-to-one branch, or ValueError."""
    top = float(rd.max(initial=0.0))
    r_max = monotonic_radius(k1, k2)
    hi = r_max if np.isfinite(r_max) else max(top, 1e-6)
    for _ in range(64):  # one-to-one everywhere: grow the table until it covers rd
        if _radial(np.array(hi), k1, k2) >= top:
            break
        hi *= 2.0
    if not _radial(np.array(hi), k1, k2) > top:
        raise ValueError(
            f"CameraEffects.k1, k2 = ({k1}, {k2}) fold the image: the lens distortion is not "
            f"one-to-one out to the image corners (normalised radius {top:.3f})"
        )
    table = np.linspace(0.0, hi, 4097)  # increasing: invert by interpolation ...
    r = np.interp(rd, _radial(table, k1, k2), table)
    with np.errstate(divide="ignore", invalid="ignore"):
        for _ in range(3):  # ... polished by Newton steps
            s = r * r
            step = (_radial(r, k1, k2) - rd) / (1.0 + s * (3.0 * k1 + 5.0 * k2 * s))
            r = np.clip(r - np.nan_to_num(step), 0.0, hi)
    if not np.all(np.abs(_radial(r, k1, k2) - rd) <= _TOL * max(1.0, top)):
        raise ValueError(  # pragma: no cover - the table brackets every radius
            f"CameraEffects.k1, k2 = ({k1}, {k2}): could not invert the lens distortion"
        )
    return r


@lru_cache(maxsize=2)
def _undistorted_grid(K: tuple, k1: float, k2: float, size: tuple[int, int]):
    """Normalised ideal coordinates ``(x_u, y_u)`` (H, W) of every output pixel, read-only."""
    k = np.array(K, dtype=np.float64).reshape(3, 3)
    w, h = size
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    x, y = _normalise(np.c_[u.ravel(), v.ravel()], k)
    rd = np.hypot(x, y)
    r = _undistort_radius(rd, k1, k2)
    scale = np.divide(r, rd, out=np.ones_like(rd), where=rd > 0)
    xu, yu = (x * scale).reshape(h, w), (y * scale).reshape(h, w)
    xu.setflags(write=False)
    yu.setflags(write=False)
    return xu, yu


def ideal_window(
    K: ArrayLike, k1: float, k2: float, size: tuple[int, int]
) -> tuple[int, int, int, int]:
    """Margins an ideal image needs around the frame for :func:`apply_camera` to see it all.

    Parameters
    ----------
    K : array_like (3, 3)
        Camera matrix of the frame.
    k1, k2 : float
        Radial distortion coefficients (OpenCV model).
    size : (int, int)
        ``(width, height)`` of the frame, px.

    Returns
    -------
    (left, top, right, bottom) : int
        Pixels (>= 0) to add on each side of a ``size`` pinhole image so that every pixel of
        the distorted frame samples inside it (with a 2 px border for interpolation and blur);
        render it with ``K`` shifted by ``(left, top)``.

    Raises
    ------
    TypeError, ValueError
        On a malformed argument (the message names it), or coefficients that fold the frame
        (not invertible out to its corners).
    """
    k = check_camera(K)
    k1 = check_number(k1, "k1")
    k2 = check_number(k2, "k2")
    w, h = check_size(size)
    if k1 == 0.0 and k2 == 0.0:
        return 0, 0, 0, 0
    xu, yu = _undistorted_grid(tuple(k.ravel()), k1, k2, (w, h))
    px = k[0, 0] * xu + k[0, 1] * yu + k[0, 2]
    py = k[1, 1] * yu + k[1, 2]
    lo = (float(px.min()), float(py.min()))
    hi = (float(px.max()), float(py.max()))
    left, top = (max(0, int(np.ceil(-v)) + 2) for v in lo)
    right = max(0, int(np.ceil(hi[0] - (w - 1))) + 2)
    bottom = max(0, int(np.ceil(hi[1] - (h - 1))) + 2)
    return left, top, right, bottom


@lru_cache(maxsize=2)
def _vignette(K: tuple, size: tuple[int, int], strength: float) -> NDArray[np.float64]:
    """Relative illumination (H, W): ``1 / (1 + a rho^2)^2``, ``1 - strength`` at the far corner."""
    w, h = size
    cx, cy = K[2], K[5]
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    d2 = (u - cx) ** 2 + (v - cy) ** 2
    far = max((x - cx) ** 2 + (y - cy) ** 2 for x in (0, w - 1) for y in (0, h - 1))
    a = 1.0 / np.sqrt(1.0 - strength) - 1.0
    out = 1.0 / (1.0 + a * d2 / max(far, 1e-12)) ** 2
    out.setflags(write=False)
    return out


def apply_camera(
    linear: ArrayLike,
    K: ArrayLike,
    effects: CameraEffects,
    *,
    rng: np.random.Generator | int | None = None,
    size: tuple[int, int] | None = None,
    ideal_K: ArrayLike | None = None,
) -> tuple[NDArray[np.uint8], dict]:
    """Turn an ideal linear-light image into the 8-bit frame a camera writes.

    Parameters
    ----------
    linear : array_like (H, W)
        Ideal pinhole image in linear light: scene radiance as grey levels (0 = black,
        255 = white paper at exposure 1; larger values saturate), each pixel the integral over
        its area. Finite and >= 0 (rounding errors down to -1e-3 are taken as 0).
    K : array_like (3, 3)
        Camera matrix of the frame; the distortion acts on its normalised coordinates.
    effects : CameraEffects
        The camera (see its attributes for the order and models).
    rng : numpy.random.Generator, int or None
        Randomness of the noise (``np.random.default_rng(rng)``).
    size : (int, int) or None
        ``(width, height)`` of the frame, px; default the size of ``linear``.
    ideal_K : array_like (3, 3) or None
        Pinhole matrix of ``linear`` (default ``K``). With ``size`` it lets ``linear`` extend
        past the frame (see :func:`ideal_window`), so that barrel distortion shows scene
        rather than a mirrored border; samples outside ``linear`` reflect its border.

    Returns
    -------
    image : ndarray (height, width) uint8
        The frame.
    params : dict
        ``effects`` as a JSON-ready dict.

    Raises
    ------
    TypeError, ValueError
        On a malformed argument (the message names it), or distortion coefficients that fold
        the frame (not invertible out to its corners).
    """
    img = _check_linear(linear)
    k = check_camera(K)
    k_ideal = k if ideal_K is None else check_camera(ideal_K)
    if not isinstance(effects, CameraEffects):
        raise TypeError(f"effects must be a CameraEffects, got {type(effects).__name__}")
    gen = check_rng(rng)
    w, h = (img.shape[1], img.shape[0]) if size is None else check_size(size)
    e = effects

    # 1. lens distortion: output pixel p_d samples the ideal image at p_u, distort(p_u) = p_d
    img = _distort_image(img, k, k_ideal, e.k1, e.k2, (w, h))
    # 2. optics and motion blur (symmetric kernels: no edge moves)
    img = _blur(img, e.blur_sigma, e.motion_blur, e.motion_angle)
    signal = img.astype(np.float64)
    # 3. vignetting, 4. exposure
    if e.vignetting > 0:
        signal *= _vignette(tuple(k.ravel()), (w, h), e.vignetting)
    if e.exposure != 1.0:
        signal *= e.exposure
    np.maximum(signal, 0.0, out=signal)
    # 5. shot noise (Poisson, as a Gaussian of variance 255 s / full_well) and read noise
    _add_sensor_noise(signal, e.full_well, e.read_noise, gen)
    v = np.clip(signal / 255.0, 0.0, 1.0)
    # 6. transfer curve, quantisation, compression
    if e.srgb:
        v = srgb_encode(v)
    out = np.rint(v * 255.0).astype(np.uint8)
    if e.jpeg_quality is not None:
        out = _jpeg_round_trip(out, e.jpeg_quality)
    return out, e.to_dict()


def _check_linear(linear: ArrayLike) -> NDArray[np.float32]:
    """:func:`apply_camera`'s ``linear`` as a float32 (H, W) array, checked (finite, >= -1e-3)
    and its small negative rounding errors set to 0."""
    try:
        img = np.asarray(linear, dtype=np.float32)
    except (TypeError, ValueError) as exc:
        raise TypeError(
            f"linear must be an (H, W) array of numbers, got {type(linear).__name__}"
        ) from exc
    if img.ndim != 2 or min(img.shape) < 1:
        raise ValueError(f"linear must have shape (H, W), got {img.shape}")
    if not np.all(np.isfinite(img)) or img.min() < -1e-3:
        raise ValueError(f"linear must be finite and >= 0, got values down to {img.min()}")
    return np.maximum(img, 0.0)


def _distort_image(img: NDArray[np.float32], k: FloatArray, k_ideal: FloatArray, k1: float,
                   k2: float, size: tuple[int, int]) -> NDArray[np.float32]:
    """The ``size`` (width, height) frame of camera ``k`` with distortion ``k1``, ``k2``
    resampled bilinearly from the ideal image ``img`` of pinhole matrix ``k_ideal`` (border
    reflected); ``img`` itself when that is the identity."""
    w, h = size
    same_grid = (w, h) == (img.shape[1], img.shape[0]) and np.array_equal(k_ideal, k)
    if k1 == 0.0 and k2 == 0.0 and same_grid:
        return img
    if k1 == 0.0 and k2 == 0.0:
        v, u = np.mgrid[0:h, 0:w].astype(np.float64)
        yu = (v - k[1, 2]) / k[1, 1]
        xu = (u - k[0, 2] - k[0, 1] * yu) / k[0, 0]
    else:
        xu, yu = _undistorted_grid(tuple(k.ravel()), k1, k2, (w, h))
    map_x = (k_ideal[0, 0] * xu + k_ideal[0, 1] * yu + k_ideal[0, 2]).astype(np.float32)
    map_y = (k_ideal[1, 1] * yu + k_ideal[1, 2]).astype(np.float32)
    return cv2.remap(img, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)


def _add_sensor_noise(signal: FloatArray, full_well: float | None, read_noise: float,
                      gen: np.random.Generator) -> None:
    """Add shot noise (a Gaussian of variance ``255 s / full_well`` at signal ``s``, the
    signal taken up to 255; none if ``full_well`` is None) and read noise (std ``read_noise``)
    to ``signal`` (grey levels) in place; no draw from ``gen`` when both are off."""
    var = np.full_like(signal, read_noise**2)
    if full_well is not None:
        var += np.minimum(signal, 255.0) * (255.0 / full_well)
    if full_well is not None or read_noise > 0:
        signal += np.sqrt(var) * gen.standard_normal(signal.shape)
