"""Render square fiducial markers with exact ground truth.

A marker is its dictionary bit pattern inside a black border one cell wide (the black square
of side ``L``), surrounded by a white quiet zone ``margin_cells`` cells wide, printed on a
plane. Its pose maps marker-frame points into the camera frame (:mod:`visloc.types`), and its
ground-truth corners are the pinhole projections of ``(-L/2, L/2, 0), (L/2, L/2, 0),
(L/2, -L/2, 0), (-L/2, -L/2, 0)``: top-left, top-right, bottom-right, bottom-left of the
marker as :func:`cv2.aruco.generateImageMarker` draws it.

Every pixel's value is the integral of the printed plane over the pixel's square (box
filter), with pixel centres at integer coordinates. By default the integral is computed
exactly from the projected cell polygons (:mod:`visloc.synth.raster`), so the edges sit where
the ground truth says to ~1e-6 px; ``supersample=S`` instead point-samples S x S positions per
pixel with :func:`cv2.warpPerspective` and averages them (edge error up to ``1 / (2 S)`` px),
which serves as an independent cross-check.

With ``camera=CameraEffects(...)`` the render is an ideal linear-light image passed through
:func:`visloc.synth.camera.apply_camera` (lens distortion, blur, vignetting, sensor noise,
sRGB encoding, JPEG); the ground-truth corners are then the distorted projections
(:func:`visloc.synth.camera.distort_points`) and ``MarkerRender.dist`` holds the distortion.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from visloc._checks import check_int
from visloc.markers.dictionary import Dictionary, load_dictionary
from visloc.synth._checks import check_camera, check_number, check_rng, check_size
from visloc.synth.camera import (
    CameraEffects,
    apply_camera,
    distort_points,
    ideal_window,
    monotonic_radius,
    srgb_decode,
)
from visloc.synth.raster import polygon_edges, window_coverages
from visloc.synth.textures import degrade, make_background
from visloc.types import Pose

FloatArray = NDArray[np.float64]

#: Black and white grey levels of the print.
BLACK, WHITE = 0.0, 255.0
#: Corners must lie at least this far (px) inside the image border for ``visible``.
VISIBLE_MARGIN = 2.0

Placement = tuple[int, Pose, float]


@dataclass(frozen=True, eq=False)
class RenderedMarker:
    """Ground truth of one marker in a render.

    Attributes
    ----------
    id : int
        Index of the marker in its dictionary.
    corners : ndarray (4, 2) float64
        Exact image corners of the black square, clockwise from the marker's own top-left
        (OpenCV order), pixel centres at integer coordinates; with lens distortion, the
        distorted projections.
    pose : Pose
        Marker-to-camera transform, ``p_cam = R @ p_marker + t``.
    length : float
        Side of the black square (border included), metres.
    visible : bool
        All four corners in front of the camera and at least 2 px inside the image border
        (within ``[1.5, W - 2.5] x [1.5, H - 2.5]``), and the printed face towards the camera.
    """

    id: int
    corners: FloatArray
    pose: Pose
    length: float
    visible: bool

    def to_dict(self) -> dict:
        """JSON-ready ground truth: ``id``, ``corners``, ``rvec``, ``tvec``, ``length``, ``visible``."""
        return {
            "id": int(self.id),
            "corners": [[float(x), float(y)] for x, y in self.corners],
            "rvec": [float(v) for v in self.pose.rvec],
            "tvec": [float(v) for v in self.pose.t],
            "length": float(self.length),
            "visible": bool(self.visible),
        }


@dataclass(frozen=True, eq=False)
class MarkerRender:
    """A synthetic image and its ground truth.

    Attributes
    ----------
    image : ndarray (H, W) uint8
        The rendered, degraded grey image.
    markers : list of RenderedMarker
        Ground truth of every placement, in the order given (drawn or not).
    K : ndarray (3, 3)
        Camera matrix.
    dictionary : str
        Name of the marker dictionary.
    params : dict
        The rendering options and degradations used (JSON-ready values); with a camera
        model, ``params["camera"]`` holds its effects.
    dist : ndarray (5,)
        OpenCV distortion coefficients ``k1, k2, p1, p2, k3`` of the image (zeros unless
        rendered with a camera model): ``K`` and ``dist`` are the image's OpenCV camera.
    """

    image: NDArray[np.uint8]
    markers: list[RenderedMarker]
    K: FloatArray
    dictionary: str
    params: dict = field(default_factory=dict)
    dist: FloatArray = field(default_factory=lambda: np.zeros(5))


def marker_object_points(length: float) -> FloatArray:
    """Marker-frame corners of a marker, in corner order.

    Parameters
    ----------
    length : float
        Side of the marker's black square, m.

    Returns
    -------
    ndarray (4, 3) float64
        ``(-L/2, L/2, 0), (L/2, L/2, 0), (L/2, -L/2, 0), (-L/2, -L/2, 0)``: top-left,
        top-right, bottom-right, bottom-left in the marker frame (:mod:`visloc.types`), m.
    """
    h = 0.5 * float(length)
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


def project_points(K: FloatArray, pose: Pose, points: FloatArray) -> FloatArray:
    """Pinhole projection of marker-frame points (no distortion).

    Parameters
    ----------
    K : ndarray (3, 3)
        Camera matrix, px.
    pose : Pose
        Marker-to-camera transform, ``p_cam = R @ p_marker + t``.
    points : ndarray (N, 3)
        Points in the marker frame, m.

    Returns
    -------
    ndarray (N, 2) float64
        Image points ``(x, y)``, px, pixel centres at integer coordinates; points in the
        camera's ``z = 0`` plane give inf or NaN, points behind the camera are projected
        through it all the same.
    """
    pc = pose.apply(points)
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = pc @ np.asarray(K, float).T
        return uv[:, :2] / uv[:, 2:3]


def faces_camera(pose: Pose) -> bool:
    """Whether the camera is on the printed (+z) side of the marker plane.

    Parameters
    ----------
    pose : Pose
        Marker-to-camera transform, ``p_cam = R @ p_marker + t``.

    Returns
    -------
    bool
    """
    return bool(np.dot(pose.t, pose.R[:, 2]) < 0.0)


def _plane_polygons(bits: NDArray[np.uint8], length: float, margin_cells: float):
    """Polygons of one marker in its plane: the quiet-zone square, and the white parts.

    Returns ``(outer, polys, weights)``: ``outer`` (4, 2) plane corners of the printed area;
    ``sum(weights[k] * [inside polys[k]])`` is 1 on white print, 0 on black and outside. The
    same marker, length and margin give the same (read-only) arrays: a map's renders reuse them.
    """
    b = np.ascontiguousarray(bits, dtype=np.uint8)
    return _polygons_of(b.tobytes(), b.shape[0], float(length), float(margin_cells))


@functools.lru_cache(maxsize=4096)
def _polygons_of(bits_bytes: bytes, s: int, length: float, margin_cells: float):
    """:func:`_plane_polygons` of the marker whose ``s x s`` bits are ``bits_bytes``."""
    bits = np.frombuffer(bits_bytes, np.uint8).reshape(s, s)
    cell = length / (s + 2)
    h = 0.5 * length
    ho = h + margin_cells * cell

    def rect(x0: float, x1: float, y0: float, y1: float) -> FloatArray:
        return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])

    outer = rect(-ho, ho, ho, -ho)
    polys = [outer, rect(-h, h, h, -h)]
    weights = [1.0, -1.0]
    for i in range(s):  # one rectangle per horizontal run of white cells
        row = np.concatenate([[0], bits[i].astype(np.int8), [0]])
        starts = np.flatnonzero(np.diff(row) == 1)
        stops = np.flatnonzero(np.diff(row) == -1)
        y_top, y_bot = h - (1 + i) * cell, h - (2 + i) * cell
        for a, b in zip(starts, stops, strict=True):
            polys.append(rect(-h + (1 + a) * cell, -h + (1 + b) * cell, y_top, y_bot))
            weights.append(1.0)
    for p in polys:
        p.setflags(write=False)
    return outer, tuple(polys), tuple(weights)


def _project_all(K: FloatArray, pose: Pose, polys: Sequence[FloatArray], near: float) -> list[FloatArray]:
    """:func:`_project_clipped` of each plane polygon: all in one projection when every vertex
    lies at ``z >= near`` (nothing to clip), else polygon by polygon."""
    ends = np.cumsum([len(q) for q in polys]).tolist()
    flat = np.zeros((ends[-1], 3))  # (a print has at least its outer square)
    flat[:, :2] = np.concatenate(polys)
    pts = pose.apply(flat)
    if not np.all(pts[:, 2] >= near):
        return [_project_clipped(K, pose, q, near) for q in polys]
    uv = pts @ K.T
    img = uv[:, :2] / uv[:, 2:3]
    return [img[a:b] for a, b in zip([0, *ends[:-1]], ends, strict=True)]


def _project_clipped(K: FloatArray, pose: Pose, poly: FloatArray, near: float) -> FloatArray:
    """Project a plane polygon (n, 2), clipped to the half-space ``z >= near``."""
    flat = np.zeros((len(poly), 3))  # the polygon on the plane z = 0
    flat[:, :2] = poly
    pts = pose.apply(flat)
    if np.all(pts[:, 2] >= near):
        kept = pts
    else:  # Sutherland-Hodgman against the near plane
        out = []
        for a, b in zip(pts, np.roll(pts, -1, axis=0), strict=True):
            if a[2] >= near:
                out.append(a)
            if (a[2] >= near) != (b[2] >= near):
                out.append(a + (near - a[2]) / (b[2] - a[2]) * (b - a))
        if len(out) < 3:
            return np.zeros((0, 2))
        kept = np.array(out)
    uv = kept @ K.T
    return uv[:, :2] / uv[:, 2:3]


def _composite_exact(canvas: FloatArray, K: FloatArray, pose: Pose, outer: FloatArray,
                     polys: Sequence[FloatArray], weights: Sequence[float], near: float) -> None:
    """Composite printed plane polygons onto ``canvas`` in place with exact area coverage.

    ``outer`` (4, 2) bounds the printed area (opaque); inside it the print is white where
    ``sum(weights[k] * [inside polys[k]])`` is 1 and black where it is 0 (plane coordinates,
    clipped to ``z >= near`` in the camera).
    """
    _composite_exact_many(canvas, K, [(pose, outer, polys, weights, near)])


def _composite_exact_many(canvas: FloatArray, K: FloatArray,
                          prints: Sequence[tuple[Pose, FloatArray, Sequence[FloatArray], Sequence[float], float]]
                          ) -> None:
    """:func:`_composite_exact` of each ``(pose, outer, polys, weights, near)`` in turn (later
    ones over earlier ones), the coverages of all of them computed in one pass
    (:func:`visloc.synth.raster.window_coverages`: each print's exactly as alone)."""
    h, w = canvas.shape
    starts, ends, wts, wins, shapes, placed = [], [], [], [], [], []
    for pose, outer, polys, weights, near in prints:
        img_outer = _project_clipped(K, pose, outer, near)
        if len(img_outer) == 0:
            continue
        c0 = int(np.clip(np.floor(img_outer[:, 0].min() + 0.5), 0, w))
        c1 = int(np.clip(np.ceil(img_outer[:, 0].max() + 0.5), 0, w))
        r0 = int(np.clip(np.floor(img_outer[:, 1].min() + 0.5), 0, h))
        r1 = int(np.clip(np.ceil(img_outer[:, 1].max() + 0.5), 0, h))
        if c1 <= c0 or r1 <= r0:
            continue
        shift = np.array([c0, r0], float)
        for polygons, poly_weights in (([img_outer - shift], [1.0]),  # alpha, then white
                                       ([q - shift for q in _project_all(K, pose, polys, near)], weights)):
            a, b, wt = polygon_edges(polygons, poly_weights)
            starts.append(a)
            ends.append(b)
            wts.append(wt)
            wins.append(np.full(len(wt), len(shapes), np.int64))
            shapes.append((r1 - r0, c1 - c0))
        placed.append((r0, r1, c0, c1))
    if not placed:
        return
    cov = window_coverages(np.concatenate(starts), np.concatenate(ends), np.concatenate(wts),
                           np.concatenate(wins), shapes)
    for i, (r0, r1, c0, c1) in enumerate(placed):
        alpha, white = cov[2 * i], cov[2 * i + 1]
        view = canvas[r0:r1, c0:c1]
        view *= 1.0 - alpha
        view += BLACK * (alpha - white) + WHITE * white


def _draw_sampled(canvas: FloatArray, K: FloatArray, pose: Pose, bits, length, margin, s: int):
    """Composite one marker onto the ``s``-times supersampled ``canvas`` by point sampling."""
    n = bits.shape[0] + 2
    cell = length / n
    ho = 0.5 * length + margin * cell
    if np.any(pose.apply(np.c_[_plane_polygons(bits, length, margin)[0], np.zeros(4)])[:, 2] <= 0):
        return  # the homography is only valid for a plane entirely in front of the camera
    # Supersampled pixel (c, r) has image coordinate x = (c + 0.5) / s - 0.5.
    to_super = np.array([[s, 0.0, 0.5 * s - 0.5], [0.0, s, 0.5 * s - 0.5], [0.0, 0.0, 1.0]])
    plane_to_img = K @ np.c_[pose.R[:, 0], pose.R[:, 1], pose.t]
    # Cell-pattern pixel (u, v) covers u - 0.5 .. u + 0.5, i.e. cell u of the marker.
    cells_to_plane = np.array(
        [[cell, 0.0, -0.5 * length + 0.5 * cell], [0.0, -cell, 0.5 * length - 0.5 * cell], [0, 0, 1]]
    )
    square_to_plane = np.diag([2.0 * ho, -2.0 * ho, 1.0])  # a 1x1 image onto the outer square
    hs, ws = canvas.shape
    flags = cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP
    pattern = (np.pad(bits, 1) * WHITE + (1 - np.pad(bits, 1)) * BLACK).astype(np.float32)
    inv = np.linalg.inv(to_super @ plane_to_img @ cells_to_plane)
    value = cv2.warpPerspective(pattern, inv, (ws, hs), flags=flags,
                                borderMode=cv2.BORDER_CONSTANT, borderValue=WHITE)
    inv = np.linalg.inv(to_super @ plane_to_img @ square_to_plane)
    inside = cv2.warpPerspective(np.ones((1, 1), np.uint8), inv, (ws, hs), flags=flags,
                                 borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    np.copyto(canvas, value, where=inside.astype(bool))


def _check_placements(placements: object, dictionary: Dictionary) -> list[Placement]:
    if not isinstance(placements, Sequence) or isinstance(placements, (str, bytes)):
        raise TypeError(f"placements must be a list of (id, Pose, length), got {type(placements).__name__}")
    out = []
    for i, item in enumerate(placements):
        if not isinstance(item, Sequence) or len(item) != 3:
            raise TypeError(f"placements[{i}] must be an (id, Pose, length) triple, got {item!r}")
        marker_id = check_int(item[0], f"placements[{i}] id", low=0, high=len(dictionary) - 1)
        if not isinstance(item[1], Pose):
            raise TypeError(f"placements[{i}] pose must be a visloc.types.Pose, got {type(item[1]).__name__}")
        pose = item[1]
        if np.shape(pose.R) != (3, 3) or np.shape(pose.t) != (3,):
            raise ValueError(f"placements[{i}] pose must have R (3, 3) and t (3,)")
        length = check_number(item[2], f"placements[{i}] length", low=0.0, low_open=True)
        out.append((marker_id, Pose(np.asarray(pose.R, float), np.asarray(pose.t, float)), length))
    if out:  # every pose a finite rotation (np.allclose(R^T R, I, atol=1e-6), det > 0), all at once
        R = np.stack([pose.R for _, pose, _ in out])
        t = np.stack([pose.t for _, pose, _ in out])
        with np.errstate(invalid="ignore"):
            ok = np.isfinite(R).all(axis=(1, 2)) & np.isfinite(t).all(axis=1)
            ok &= (np.abs(R.mT @ R - np.eye(3)) <= 1e-6 + 1e-5 * np.eye(3)).all(axis=(1, 2))
            ok &= ~(np.linalg.det(np.where(ok[:, None, None], R, np.eye(3))) < 0)
        if not ok.all():  # a NaN pose used to render as no marker at all, with NaN corners as its truth
            i = int(np.argmin(ok))
            raise ValueError(f"placements[{i}] pose: R must be a finite rotation matrix and t finite")
    return out


def render_markers(
    K: FloatArray, size: tuple[int, int], placements: Sequence[Placement], dictionary: str | Dictionary, *,
    background: str | NDArray[np.uint8] | None = None, supersample: int | None = None, margin_cells: float = 1.0,
    blur_sigma: float = 0.0, motion_blur: float = 0.0, motion_angle: float = 0.0, noise_sigma: float = 0.0,
    gain: float = 1.0, gradient: float = 0.0, jpeg_quality: int | None = None,
    rng: np.random.Generator | int | None = None, camera: CameraEffects | None = None,
) -> MarkerRender:
    """Render markers seen by a pinhole camera, with exact ground-truth corners.

    Parameters
    ----------
    K : ndarray (3, 3)
        Camera matrix (the pinhole part of the camera).
    size : (int, int)
        ``(width, height)`` of the image.
    placements : list of (int, Pose, float)
        ``(id, pose, length)`` per marker: dictionary id, marker-to-camera pose and side of
        the black square in metres. Markers behind the camera or seen from the back are not
        drawn (their ground truth is still returned, with ``visible=False``); nearer markers
        are drawn over farther ones.
    dictionary : str or Dictionary
        Marker dictionary (see :func:`visloc.markers.dictionary.load_dictionary`).
    background : str, ndarray (H, W) uint8 or None
        ``'grass'``, ``'gravel'``, ``'brick'`` (CC0 photographs, see visloc/synth/data), ``'noise'`` (smooth
        random texture), ``'flat'`` (grey 128, the default) or an image of the render's size.
    supersample : int or None
        ``None`` (default): exact pixel area coverage. ``S >= 1``: point-sample ``S x S``
        positions per pixel (supersampled pixel ``(r, c)`` at image coordinate
        ``((c + 0.5) / S - 0.5, (r + 0.5) / S - 0.5)``) with :func:`cv2.warpPerspective`
        and average them; markers partly behind the camera are then skipped.
    margin_cells : float
        Width of the white quiet zone around the black square, in cells (>= 0).
    blur_sigma : float
        Gaussian optical blur, standard deviation in pixels (>= 0).
    motion_blur, motion_angle : float
        Linear motion blur length in pixels (>= 0) and direction in radians.
    noise_sigma : float
        Standard deviation of additive Gaussian noise in grey levels (>= 0).
    gain : float
        Exposure factor (> 0); below 1 simulates dim light.
    gradient : float
        Strength in [0, 1) of a multiplicative illumination ramp falling from 1 to
        ``1 - gradient`` across the image in a random direction.
    jpeg_quality : int or None
        JPEG round-trip quality in [1, 100], or ``None`` for none.
    rng : numpy.random.Generator, int or None
        Randomness for noise, gradient direction and textures (``np.random.default_rng(rng)``).
    camera : CameraEffects or None
        A camera model instead of the degradations above (which must then keep their
        defaults): the markers and the background (its grey levels taken as sRGB-encoded and
        decoded to linear light) form an ideal linear-light image, extended past the frame as
        far as the lens distortion looks, which :func:`visloc.synth.camera.apply_camera` turns
        into the frame. Ground-truth corners and ``visible`` are then those of the distorted
        projections (and a corner must lie where the distortion is still one-to-one).

    Returns
    -------
    MarkerRender
        Image, per-placement ground truth, ``K``, ``dist`` and the parameters used.

    Raises
    ------
    TypeError, ValueError
        On a malformed argument; the message names it.
    """
    k = check_camera(K)
    w, h = check_size(size)
    dic = load_dictionary(dictionary)
    items = _check_placements(placements, dic)
    if supersample is not None:
        supersample = check_int(supersample, "supersample", low=1, high=32)
    margin_cells = check_number(margin_cells, "margin_cells", low=0.0)
    deg, gen = _check_degradations(camera, rng, blur_sigma=blur_sigma, motion_blur=motion_blur,
                                   motion_angle=motion_angle, noise_sigma=noise_sigma, gain=gain,
                                   gradient=gradient, jpeg_quality=jpeg_quality)
    bg, bg_name, k_ideal = _ideal_background(k, (w, h), background, camera, gen)
    markers = _marker_truths(k, (w, h), camera, items)
    canvas = _draw_markers(bg, k_ideal, items, dic, supersample, margin_cells)
    params = {"background": bg_name, "supersample": supersample, "margin_cells": margin_cells}
    return _finish(canvas, k, k_ideal, (w, h), markers, dic.name, params, camera, gen, **deg)


def _draw_markers(bg: FloatArray, k_ideal: FloatArray, items: Sequence[Placement],
                  dic: Dictionary, supersample: int | None, margin_cells: float) -> FloatArray:
    """The ideal canvas (H, W) float64: the placements facing the camera composited onto the
    background ``bg`` (modified in place when exact), farthest first, by exact area coverage
    or, with ``supersample`` S, by point sampling S x S positions per pixel."""
    order = sorted(range(len(items)), key=lambda i: -float(np.linalg.norm(items[i][1].t)))
    drawn = [i for i in order if faces_camera(items[i][1])]
    if supersample is None:
        prints = [(pose, *_plane_polygons(dic.bits[marker_id], length, margin_cells), 1e-6 * length)
                  for marker_id, pose, length in (items[i] for i in drawn)]
        _composite_exact_many(bg, k_ideal, prints)
        return bg
    s = supersample
    hc, wc = bg.shape
    canvas = np.repeat(np.repeat(bg.astype(np.float32), s, axis=0), s, axis=1)
    for i in drawn:
        marker_id, pose, length = items[i]
        _draw_sampled(canvas, k_ideal, pose, dic.bits[marker_id], length, margin_cells, s)
    return canvas.reshape(hc, s, wc, s).astype(np.float64).mean(axis=(1, 3))


def _ideal_background(
    k: FloatArray,
    size: tuple[int, int],
    background: str | NDArray[np.uint8] | None,
    camera: CameraEffects | None,
    gen: np.random.Generator,
) -> tuple[FloatArray, str, FloatArray]:
    """The canvas to draw on, the background's name and the canvas's pinhole matrix: the
    frame itself, or with a camera model the linear-light image extended past the frame as
    far as the lens distortion looks."""
    w, h = size
    if camera is None:
        bg, bg_name = make_background(background, (w, h), gen)
        return bg, bg_name, k
    left, top, right, bottom = ideal_window(k, camera.k1, camera.k2, (w, h))
    bg, bg_name = _camera_background(background, (w, h), (left, top, right, bottom), gen)
    k_ideal = k.copy()
    k_ideal[:2, 2] += (left, top)
    return bg, bg_name, k_ideal


def _marker_truths(k: FloatArray, size: tuple[int, int], camera: CameraEffects | None,
                   items: Sequence[Placement]) -> list[RenderedMarker]:
    """Ground truth of each ``(id, pose, length)`` placement: its (distorted) corner
    projections and whether it is visible (in front, inside the frame by
    :data:`VISIBLE_MARGIN`, facing the camera, and with a lens model where the distortion is
    one-to-one), all markers projected at once."""
    if not items:
        return []
    w, h = size
    obj = np.stack([marker_object_points(length) for _, _, length in items])  # (M, 4, 3)
    pc = obj @ np.stack([pose.R for _, pose, _ in items]).mT + np.stack([pose.t for _, pose, _ in items])[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = pc @ np.asarray(k, float).T
        corners = uv[..., :2] / uv[..., 2:3]  # project_points of each
    in_front = (pc[..., 2] > 0).all(axis=1)
    if camera is not None:
        one_to_one = _within_radius(corners, k, monotonic_radius(camera.k1, camera.k2))
        corners = distort_points(corners.reshape(-1, 2), k, camera.k1, camera.k2).reshape(-1, 4, 2)
        in_front &= one_to_one
    with np.errstate(invalid="ignore"):
        inside = (np.isfinite(corners).all(axis=(1, 2)) & (corners >= VISIBLE_MARGIN - 0.5).all(axis=(1, 2))
                  & (corners <= np.array([w, h]) - 0.5 - VISIBLE_MARGIN).all(axis=(1, 2)))
    return [RenderedMarker(marker_id, c, pose, length, bool(front and ok) and faces_camera(pose))
            for (marker_id, pose, length), c, front, ok in zip(items, corners, in_front.tolist(), inside.tolist(),
                                                                strict=True)]


def _finish(canvas: FloatArray, k: FloatArray, k_ideal: FloatArray, size: tuple[int, int],
            markers: list[RenderedMarker], dictionary: str, params: dict,
            camera: CameraEffects | None, gen: np.random.Generator, *, blur_sigma: float,
            motion_blur: float, motion_angle: float, noise_sigma: float, gain: float,
            gradient: float, jpeg_quality: int | None) -> MarkerRender:
    """Turn the ideal canvas into the frame (degradations or camera model) and pack the
    render; ``params`` holds the renderer's own options, the degradations are added."""
    if camera is None:
        image, grad_angle = degrade(
            canvas, gen, blur_sigma=blur_sigma, motion_blur=motion_blur,
            motion_angle=motion_angle, gradient=gradient, gain=gain, noise_sigma=noise_sigma,
            jpeg_quality=jpeg_quality,
        )
    else:
        image, camera_params = apply_camera(canvas, k, camera, rng=gen, size=size, ideal_K=k_ideal)
        grad_angle = None
    params = {
        **params,
        "blur_sigma": blur_sigma,
        "motion_blur": motion_blur,
        "motion_angle": motion_angle,
        "noise_sigma": noise_sigma,
        "gain": gain,
        "gradient": gradient,
        "gradient_angle": grad_angle,
        "jpeg_quality": jpeg_quality,
    }
    if camera is None:
        return MarkerRender(image, markers, k, dictionary, params)
    params["camera"] = camera_params
    return MarkerRender(image, markers, k, dictionary, params, camera.dist)


def _check_degradations(camera: object, rng: object, *, blur_sigma: object, motion_blur: object,
                        motion_angle: object, noise_sigma: object, gain: object, gradient: object,
                        jpeg_quality: object) -> tuple[dict, np.random.Generator]:
    """The renderers' degradation arguments checked (a ValueError or TypeError naming the
    one at fault; with ``camera`` they must keep their defaults), and the generator of
    ``rng``."""
    deg = {
        "blur_sigma": check_number(blur_sigma, "blur_sigma", low=0.0),
        "motion_blur": check_number(motion_blur, "motion_blur", low=0.0),
        "motion_angle": check_number(motion_angle, "motion_angle"),
        "noise_sigma": check_number(noise_sigma, "noise_sigma", low=0.0),
        "gain": check_number(gain, "gain", low=0.0, low_open=True),
        "gradient": check_number(gradient, "gradient", low=0.0, high=1.0, high_open=True),
        "jpeg_quality": None if jpeg_quality is None else check_int(jpeg_quality, "jpeg_quality", low=1, high=100),
    }
    gen = check_rng(rng)
    if camera is not None:
        _check_camera_effects(camera, **deg)
    return deg, gen


def _check_camera_effects(camera: object, **degradations: object) -> None:
    """``camera`` must be a CameraEffects and the ``degrade`` options at their defaults."""
    if not isinstance(camera, CameraEffects):
        raise TypeError(f"camera must be a CameraEffects or None, got {type(camera).__name__}")
    defaults = {"blur_sigma": 0.0, "motion_blur": 0.0, "motion_angle": 0.0, "noise_sigma": 0.0,
                "gain": 1.0, "gradient": 0.0, "jpeg_quality": None}
    changed = [f"{name}={value!r}" for name, value in degradations.items()
               if value != defaults[name]]
    if changed:
        raise ValueError(
            f"{', '.join(changed)}: with camera, the degradation arguments must keep their "
            "defaults (set the CameraEffects fields instead)"
        )


def _camera_background(
    background: str | NDArray[np.uint8] | None,
    size: tuple[int, int],
    pad: tuple[int, int, int, int],
    rng: np.random.Generator,
) -> tuple[FloatArray, str]:
    """Linear-light background of the frame ``size`` extended by ``pad`` (left, top, right,
    bottom): named textures are made at the extended size, a given image is mirrored out."""
    w, h = size
    left, top, right, bottom = pad
    if isinstance(background, np.ndarray):
        bg, name = make_background(background, (w, h), rng)
        bg = cv2.copyMakeBorder(bg, top, bottom, left, right, cv2.BORDER_REFLECT)
    else:
        bg, name = make_background(background, (w + left + right, h + top + bottom), rng)
    return srgb_decode(bg / 255.0) * 255.0, name


def _within_radius(points: FloatArray, K: FloatArray, radius: float) -> NDArray[np.bool_]:
    """For each set of pinhole points (..., N, 2): all finite and closer than ``radius`` to
    the optical axis (normalised coordinates); shape ``points.shape[:-2]``."""
    finite = np.isfinite(points).all(axis=(-2, -1))
    y = (points[..., 1] - K[1, 2]) / K[1, 1]
    x = (points[..., 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
    with np.errstate(invalid="ignore"):  # (NaN points: not finite already)
        return finite & (np.hypot(x, y) < radius).all(axis=-1)
