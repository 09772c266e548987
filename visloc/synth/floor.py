"""Fast views of a marker map lying on the floor: the map printed once as a ground texture.

:func:`visloc.synth.render_map_view` rasterises every marker exactly for each view (tens of
ms); a simulation loop that renders a bottom-camera frame at every camera tick needs a few
ms. :class:`FloorTexture` prints the map once onto a white floor (``metres_per_texel`` per
texel, each texel the covered fraction of its area) and :meth:`FloorTexture.render` samples it through the
camera with the ground renderer of :mod:`visloc.synth.flight` (mip-mapped bilinear samples,
``supersample`` per pixel axis). Corner accuracy is that of the texture (about a tenth of a
texel), which is what a closed-loop test needs; the exact renderer stays the reference for
detector accuracy.

Geometry: the map's markers must lie in its ``z = 0`` plane with ``z`` up (the floor seen from
above), as :func:`visloc.pose.GridMap` builds them.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np
from numpy.typing import NDArray

from visloc._checks import check_int
from visloc.markers.dictionary import Dictionary, load_dictionary
from visloc.pose.maps import MarkerMap
from visloc.synth._checks import check_camera, check_number, check_size
from visloc.synth.flight import _mipmap, _render, _texture_level
from visloc.synth.textures import degrade
from visloc.types import FloatArray, Pose

__all__ = ["FloorTexture"]

_SHIFT = 4  # sub-pixel bits of cv2.fillConvexPoly
_SUPER = 8  # fine samples per texel side when printing a marker


@dataclass(frozen=True, eq=False)
class FloorTexture:
    """A marker map printed on a white floor, ready to be viewed from any camera pose above it.

    Attributes
    ----------
    levels : tuple of ndarray (H, W) uint8
        Mip-map of the printed floor (grey levels 0-255, rounded: a quarter of float32's
        memory, which a simulation rendering every frame feels in the cache), texel ``(u, v)``
        at map point ``origin + (u, v) * metres_per_texel``.
    origin : ndarray (2,)
        Map ``(x, y)`` of texel ``(0, 0)``, m.
    metres_per_texel : float
    marker_map : MarkerMap
    """

    levels: tuple[NDArray[np.uint8], ...]
    origin: FloatArray
    metres_per_texel: float
    marker_map: MarkerMap

    @classmethod
    def from_map(cls, marker_map: MarkerMap, dictionary: str | Dictionary, *,
                 metres_per_texel: float = 0.0015, margin: float = 1.5) -> FloorTexture:
        """Print ``marker_map`` (markers of ``dictionary``) with ``margin`` m of white floor.

        Parameters
        ----------
        marker_map : MarkerMap
            Markers in the map's z = 0 plane.
        dictionary : str or Dictionary
            Their dictionary (name or loaded).
        metres_per_texel : float
            Texel size, m (> 0); keep it below a third of a marker cell.
        margin : float
            White floor around the map's bounding box, m (>= 0). Beyond it the floor is
            mirror-tiled, so keep the camera's footprint inside it.

        Raises
        ------
        ValueError
            If a marker is not in the z = 0 plane, or its id is not in the dictionary.
        """
        if not isinstance(marker_map, MarkerMap):
            raise TypeError(f"marker_map: expected a MarkerMap, got {type(marker_map).__name__}")
        dic = dictionary if isinstance(dictionary, Dictionary) else load_dictionary(dictionary)
        mpt = check_number(metres_per_texel, "metres_per_texel", low=0.0, low_open=True)
        pad = check_number(margin, "margin", low=0.0)
        corners = {int(i): marker_map.corners_of(int(i)) for i in marker_map.ids}
        pts = np.concatenate(list(corners.values()))
        if np.max(np.abs(pts[:, 2])) > 1e-9:
            raise ValueError("marker_map: every marker must lie in the map's z = 0 plane")
        lo = pts[:, :2].min(axis=0) - pad
        size = np.ceil((pts[:, :2].max(axis=0) + pad - lo) / mpt).astype(int) + 1
        size += size % 2  # even sides keep the mip-map levels aligned
        floor = np.full((int(size[1]), int(size[0])), 255, np.uint8)
        for marker_id, quad in corners.items():
            if not 0 <= marker_id < len(dic):
                raise ValueError(f"marker_map: id {marker_id} is not in {dic.name} "
                                 f"(0-{len(dic) - 1})")
            _print_marker(floor, dic.bits[marker_id], (quad[:, :2] - lo) / mpt)
        levels = tuple(np.clip(np.rint(level), 0, 255).astype(np.uint8) for level in _mipmap(floor))
        return cls(levels, lo, mpt, marker_map)

    def render(self, K: NDArray, size: tuple[int, int], T_cam_map: Pose, *, supersample: int = 2,
               noise_sigma: float = 0.0, blur_sigma: float = 0.0,
               rng: np.random.Generator | None = None, fast_noise: bool = False) -> NDArray[np.uint8]:
        """The floor seen by a pinhole camera at ``T_cam_map`` (above the floor, looking down).

        Parameters
        ----------
        K : ndarray (3, 3)
            Camera matrix.
        size : (int, int)
            ``(width, height)``.
        T_cam_map : Pose
            ``p_cam = R @ p_map + t``; the camera centre must be above the floor (z > 0).
        supersample : int
            Samples per pixel axis (1-8).
        noise_sigma, blur_sigma : float
            Gaussian sensor noise (grey levels) and optical blur (px), >= 0.
        rng : numpy.random.Generator, optional
            Noise source.
        fast_noise : bool
            Draw the noise with OpenCV (:func:`visloc.synth.textures.degrade`).

        Returns
        -------
        ndarray (H, W) uint8

        Raises
        ------
        ValueError
            If part of the view misses the floor, or the camera is not above it.
        """
        K, k_inv = _camera(K)
        w, h = check_size(size)
        if not isinstance(T_cam_map, Pose):
            raise TypeError(f"T_cam_map: expected a Pose, got {type(T_cam_map).__name__}")
        s = check_int(supersample, "supersample", low=1, high=8)
        R_map_cam = T_cam_map.R.T
        C = -R_map_cam @ T_cam_map.t
        if C[2] <= 0.0:
            raise ValueError(f"T_cam_map: the camera centre must be above the floor, got z = {C[2]:.4g} m")
        centre = C.copy()
        centre[:2] -= self.origin  # texel (0, 0) at the ground renderer's origin
        img = _warped(self.levels, K, (w, h), R_map_cam, centre, self.metres_per_texel, s, k_inv=k_inv)
        if img is None:  # the view leaves the printed floor's texture: its mirror tiling
            img = _render(self.levels, K, (w, h), R_map_cam, centre, self.metres_per_texel, s)
        noise = check_number(noise_sigma, "noise_sigma", low=0.0)
        blur = check_number(blur_sigma, "blur_sigma", low=0.0)
        if noise == 0.0 and blur == 0.0 and img.dtype == np.uint8:  # nothing to degrade: degrade's own result
            return img
        return degrade(img, rng if rng is not None else np.random.default_rng(), blur_sigma=blur,
                       noise_sigma=noise, fast_noise=bool(fast_noise))[0]


def _camera(K: object) -> tuple[FloatArray, FloatArray]:
    """``K`` checked (:func:`~visloc.synth._checks.check_camera`) and its inverse; a float64
    (3, 3) array is looked up by its values (a video's frames share one camera)."""
    if isinstance(K, np.ndarray) and K.dtype == np.float64 and K.shape == (3, 3):
        return _camera_of(K.tobytes())
    K = check_camera(K)
    return K, np.linalg.inv(K)


@lru_cache(maxsize=16)
def _camera_of(values: bytes) -> tuple[FloatArray, FloatArray]:
    """:func:`_camera` of a K given by its float64 bytes (both read-only: they are shared)."""
    K = check_camera(np.frombuffer(values, np.float64).reshape(3, 3))
    k_inv = np.linalg.inv(K)
    K.setflags(write=False)
    k_inv.setflags(write=False)
    return K, k_inv


def _warped(levels: tuple[NDArray, ...], K: FloatArray, size: tuple[int, int], R: FloatArray,
            C: FloatArray, mpt: float, s: int, *, k_inv: FloatArray | None = None) -> NDArray | None:
    """The view of :func:`visloc.synth.flight._render` by one ``cv2.warpPerspective`` of the
    texture level: the floor plane maps to the image by a homography, so the texture is
    warped (bilinear, ``s`` x ``s`` samples per pixel averaged) instead of sampled through
    per-pixel rays (the same grey levels to about 0.05, in under half the time at 320 x 240), in
    the levels' type (uint8 for a :class:`FloorTexture`: rounded at each sample and mean). None
    when the view reaches beyond the texture, whose mirror tiling ``_render`` keeps."""
    w, h = size
    k_inv = np.linalg.inv(K) if k_inv is None else k_inv  # (K's inverse)
    tex, scale = _texture_level(levels, K, size, R, C, mpt, k_inv)
    k = -C[2] / (mpt * scale)  # ray length to the ground per unit ray z, in texels
    off = C[:2] / (mpt * scale) + 0.5 / scale - 0.5  # the camera's texel, in the level's coordinates
    to_tex = np.vstack([k * R[0] + off[0] * R[2], k * R[1] + off[1] * R[2], R[2]]) @ k_inv
    sample = np.array([[1.0 / s, 0.0, 0.5 / s - 0.5], [0.0, 1.0 / s, 0.5 / s - 0.5], [0.0, 0.0, 1.0]])
    H = to_tex @ sample  # sample (column, row) -> texel (u, v)
    edge = np.array([[-0.5, w * s - 0.5, w * s - 0.5, -0.5], [-0.5, -0.5, h * s - 0.5, h * s - 0.5], [1.0] * 4])
    uv = H @ edge
    uv = uv[:2] / uv[2]
    if uv.min() < 0.0 or uv[0].max() > tex.shape[1] - 1 or uv[1].max() > tex.shape[0] - 1:
        return None
    # every sample lies inside the texture (checked above), so no border pixel is read; OpenCV's
    # constant-border warp is its faster path (about a fifth at 320 x 240), whose rounding differs
    # from the reflecting one's by a grey level on about 0.1 % of the pixels
    img = cv2.warpPerspective(tex, H, (w * s, h * s), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                              borderMode=cv2.BORDER_CONSTANT)
    return img if s == 1 else cv2.resize(img, (w, h), interpolation=cv2.INTER_AREA)  # S x S mean


def _print_marker(floor: NDArray[np.uint8], bits: NDArray[np.uint8], quad: FloatArray) -> None:
    """Print one marker whose corners (TL, TR, BR, BL) are ``quad`` in texel coordinates.

    The black cells (border and 0 bits) are filled on a patch sampled ``_SUPER`` times finer
    and averaged down (``INTER_AREA``): each texel gets its covered fraction, with no shift of
    the edges (antialiased polygon filling would dilate the black cells by up to half a texel).
    """
    n = bits.shape[0] + 2
    grid = np.pad(bits, 1)
    lo = np.floor(quad.min(axis=0)).astype(int) - 1
    hi = np.ceil(quad.max(axis=0)).astype(int) + 2
    lo = np.maximum(lo, 0)
    hi = np.minimum(hi, [floor.shape[1], floor.shape[0]])
    if np.any(hi <= lo):
        return
    w, h = hi - lo
    patch = np.full((h * _SUPER, w * _SUPER), 255, np.uint8)
    fine = (quad - lo + 0.5) * _SUPER - 0.5  # texel centres -> the fine patch's pixel centres
    tl, tr, bl = fine[0], fine[1], fine[3]
    ex, ey = (tr - tl) / n, (bl - tl) / n
    for r in range(n):
        for c in range(n):
            if grid[r, c]:
                continue
            a = tl + c * ex + r * ey
            cell = np.array([a, a + ex, a + ex + ey, a + ey])
            pts = np.round(cell * (1 << _SHIFT)).astype(np.int32)
            cv2.fillConvexPoly(patch, pts, 0, lineType=cv2.LINE_8, shift=_SHIFT)
    small = cv2.resize(patch, (int(w), int(h)), interpolation=cv2.INTER_AREA)
    view = floor[lo[1]:hi[1], lo[0]:hi[0]]
    np.minimum(view, small, out=view)
