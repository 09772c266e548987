"""Render AprilGrid calibration boards (Kalibr's layout) with exact ground truth.

An AprilGrid is ``rows x cols`` tags of side ``L`` (the black square, one-cell border
included) separated by gaps ``s = spacing_ratio * L``, with a black square of side ``s`` at
every gap intersection, the outer corners of the grid included: each tag touches four corner
squares, exactly at its own four corners (one point each), so a tag's black border is *not*
an isolated closed outline. A white margin ``s`` wide surrounds the outer corner squares.

Board frame (that of :func:`visloc.pose.maps.GridMap` with ``spacing = s``): origin at the
top-left corner of the first tag's black square, x to the right along a row, y up (the rows
lie at negative y), z out of the printed face. Tag ``(r, c)`` (row ``r`` from the top) has id
``first_id + r * cols + c`` and its top-left corner at ``(c (L + s), -r (L + s), 0)``; every
tag is printed upright (its own top towards board +y). Note that Kalibr numbers its tags from
the bottom-left instead.

The board is drawn as :func:`visloc.synth.markers.render_markers` draws a marker (exact pixel
area coverage of the projected polygons) and goes through the same degradations or camera
model; the ground truth is one :class:`~visloc.synth.markers.RenderedMarker` per tag.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from visloc._checks import check_int
from visloc.markers.dictionary import Dictionary, load_dictionary
from visloc.synth._checks import check_camera, check_number, check_rng, check_size
from visloc.synth.camera import CameraEffects
from visloc.synth.markers import (
    MarkerRender,
    _check_degradations,
    _composite_exact,
    _finish,
    _ideal_background,
    _marker_truths,
    _plane_polygons,
    faces_camera,
)
from visloc.synth.scenes import (
    _camera_effects,
    _degradations,
    _rotation_to,
    default_camera,
)
from visloc.synth.textures import TEXTURES
from visloc.types import Pose

FloatArray = NDArray[np.float64]

#: Difficulty levels of :func:`random_board_scene`.
BOARD_DIFFICULTIES = ("easy", "hard")
#: Side (m) of the tags of random board scenes.
BOARD_TAG_LENGTH = 0.04
#: Gap between tags, as a fraction of the tag side, in random board scenes (Kalibr's default).
BOARD_SPACING_RATIO = 0.3

# Tag side in the image of random board scenes: fraction of the image height and least pixels.
_TAG_FRACTION = (0.06, 0.12)
_MIN_TAG_PX = 20.0
_MAX_TILT_DEG = 40.0


def _rect(x0: float, x1: float, y0: float, y1: float) -> FloatArray:
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])


def aprilgrid_tag_corners(rows: int, cols: int, tag_length: float, *,
                          spacing_ratio: float = 0.3) -> FloatArray:
    """Board-frame corners of every tag of an AprilGrid, in id order.

    Parameters
    ----------
    rows, cols : int
        Grid size: tags per column and per row (>= 1).
    tag_length : float
        Side of a tag's black square, m (> 0).
    spacing_ratio : float
        Gap between tags over ``tag_length`` (> 0).

    Returns
    -------
    ndarray (rows * cols, 4, 3) float64
        Per tag (row by row from the top-left tag), its corners in the board frame (module
        docstring), m, clockwise from its own top-left (OpenCV order), z = 0.

    Raises
    ------
    TypeError, ValueError
        On a malformed argument; the message names it.
    """
    rows = check_int(rows, "rows", low=1)
    cols = check_int(cols, "cols", low=1)
    L = check_number(tag_length, "tag_length", low=0.0, low_open=True)
    s = check_number(spacing_ratio, "spacing_ratio", low=0.0, low_open=True) * L
    pitch = L + s
    square = np.array([[0.0, 0.0, 0.0], [L, 0.0, 0.0], [L, -L, 0.0], [0.0, -L, 0.0]])
    r, c = np.divmod(np.arange(rows * cols), cols)
    offsets = np.stack([c * pitch, -r * pitch, np.zeros(r.size)], axis=1)
    return square[None] + offsets[:, None]


def _board_polygons(dic: Dictionary, ids: list[int], rows: int, cols: int, L: float, s: float):
    """Plane polygons of the board: its outline and the weighted polygons whose sum is 1 on
    white print and 0 on black (see :func:`visloc.synth.markers._composite_exact`)."""
    pitch = L + s
    outer = _rect(-2.0 * s, cols * pitch + s, 2.0 * s, -rows * pitch - s)
    polys, weights = [outer], [1.0]
    for k, marker_id in enumerate(ids):
        r, c = divmod(k, cols)
        centre = np.array([c * pitch + 0.5 * L, -r * pitch - 0.5 * L])
        # _plane_polygons without a quiet zone: [square (+1), square (-1), white runs (+1)];
        # dropping the first leaves the tag as black print with white cells on the board.
        _, tag, tag_w = _plane_polygons(dic.bits[marker_id], L, 0.0)
        polys.extend(p + centre for p in tag[1:])
        weights.extend(tag_w[1:])
    for r in range(rows + 1):  # corner squares at every gap intersection
        for c in range(cols + 1):
            x, y = c * pitch, -r * pitch
            polys.append(_rect(x - s, x, y + s, y))
            weights.append(-1.0)
    return outer, polys, weights


def render_aprilgrid(
    K: FloatArray,
    size: tuple[int, int],
    pose: Pose,
    *,
    rows: int,
    cols: int,
    tag_length: float,
    spacing_ratio: float = 0.3,
    dictionary: str | Dictionary = "DICT_APRILTAG_36h11",
    first_id: int = 0,
    background: str | NDArray[np.uint8] | None = None,
    blur_sigma: float = 0.0,
    motion_blur: float = 0.0,
    motion_angle: float = 0.0,
    noise_sigma: float = 0.0,
    gain: float = 1.0,
    gradient: float = 0.0,
    jpeg_quality: int | None = None,
    camera: CameraEffects | None = None,
    rng: np.random.Generator | int | None = None,
) -> MarkerRender:
    """Render an AprilGrid (Kalibr's layout) seen by a pinhole camera, with exact ground truth.

    Parameters
    ----------
    K, size : as :func:`~visloc.synth.markers.render_markers`
    pose : Pose
        Board-to-camera transform (board frame in the module docstring: origin at the
        top-left corner of the first tag, x right, y up, z out of the face). A board seen
        from the back is not drawn (its tags are then not ``visible``).
    rows, cols : int
        Tags per column and per row (>= 1).
    tag_length : float
        Side of each tag's black square (its one-cell border included), m (> 0).
    spacing_ratio : float
        Gap between neighbouring tags over ``tag_length``, in (0, 10]; it is also the side
        of the corner squares and the width of the white margin over ``tag_length``.
    dictionary : str or Dictionary
        Tag dictionary; each tag is drawn as OpenCV draws it with ``borderBits=1``.
    first_id : int
        Id of the top-left tag; ids run row by row, ``first_id + rows * cols - 1`` at most the
        dictionary's last id.
    background : str, ndarray (H, W) uint8 or None
        Background around the board, as for :func:`~visloc.synth.markers.render_markers`.
    blur_sigma, motion_blur, motion_angle, noise_sigma, gain, gradient : float
        Degradations (px, px, rad, grey levels, factor, fraction), as for
        :func:`~visloc.synth.markers.render_markers` (defaults: none but 8-bit quantisation);
        they must keep their defaults with ``camera``.
    jpeg_quality : int or None
        JPEG round-trip quality in [1, 100] (as for
        :func:`~visloc.synth.markers.render_markers`), or ``None``; ``None`` with ``camera``.
    camera : CameraEffects or None
        A camera model (as for :func:`~visloc.synth.markers.render_markers`): the ground-truth
        corners are then the distorted projections and ``dist`` holds the distortion.
    rng : numpy.random.Generator, int or None
        Randomness for noise and textures.

    Returns
    -------
    MarkerRender
        ``markers`` holds one :class:`RenderedMarker` per tag in id order (pose: tag-to-camera,
        tag frame at the tag's centre, axes of the board's); ``params`` also holds ``rows``,
        ``cols``, ``tag_length``, ``spacing_ratio``, ``first_id`` and the board pose
        (``board_rvec``, ``board_tvec``).

    Raises
    ------
    TypeError, ValueError
        On a malformed argument, or when the dictionary does not hold ``rows * cols`` ids
        from ``first_id`` on; the message names it.
    """
    k = check_camera(K)
    w, h = check_size(size)
    pose = _check_board_pose(pose)
    grid = _check_grid(rows, cols, tag_length, spacing_ratio, dictionary, first_id)
    deg, gen = _check_degradations(camera, rng, blur_sigma=blur_sigma, motion_blur=motion_blur,
                                   motion_angle=motion_angle, noise_sigma=noise_sigma, gain=gain,
                                   gradient=gradient, jpeg_quality=jpeg_quality)
    return _render_aprilgrid(k, (w, h), pose, grid, background, camera, gen, deg)


class _Grid(NamedTuple):
    """The AprilGrid arguments of :func:`render_aprilgrid`, checked."""

    rows: int
    cols: int
    tag_length: float
    spacing_ratio: float
    dictionary: Dictionary
    first_id: int


def _check_board_pose(pose: object) -> Pose:
    """``pose`` checked to be a Pose of a finite rotation and a finite translation, as a Pose of
    float arrays."""
    if not isinstance(pose, Pose):
        raise TypeError(f"pose must be a visloc.types.Pose, got {type(pose).__name__}")
    R, t = np.asarray(pose.R, float), np.asarray(pose.t, float)
    if R.shape != (3, 3) or t.shape != (3,):
        raise ValueError(f"pose must have R (3, 3) and t (3,), got {R.shape} and {t.shape}")
    if not (np.all(np.isfinite(R)) and np.all(np.isfinite(t))) or not np.allclose(
        R.T @ R, np.eye(3), atol=1e-6
    ) or np.linalg.det(R) < 0:
        raise ValueError("pose.R must be a finite rotation matrix and pose.t finite")
    return Pose(R, t)


def _check_grid(rows: object, cols: object, tag_length: object, spacing_ratio: object,
                dictionary: str | Dictionary, first_id: object) -> _Grid:
    """The grid arguments of :func:`render_aprilgrid` checked, the dictionary loaded; it must
    hold the ``rows * cols`` ids from ``first_id`` on."""
    rows = check_int(rows, "rows", low=1, high=1000)
    cols = check_int(cols, "cols", low=1, high=1000)
    L = check_number(tag_length, "tag_length", low=0.0, low_open=True)
    spacing_ratio = check_number(spacing_ratio, "spacing_ratio", low=0.0, high=10.0,
                                 low_open=True)
    dic = load_dictionary(dictionary)
    n = rows * cols
    if n > len(dic):
        raise ValueError(f"rows * cols must be at most {len(dic)} ({dic.name}), got {n}")
    first_id = check_int(first_id, "first_id", low=0, high=len(dic) - n)
    return _Grid(rows, cols, L, spacing_ratio, dic, first_id)


def _render_aprilgrid(k: FloatArray, size: tuple[int, int], pose: Pose, grid: _Grid,
                      background: str | NDArray[np.uint8] | None, camera: CameraEffects | None,
                      gen: np.random.Generator, deg: dict) -> MarkerRender:
    """:func:`render_aprilgrid` from its checked arguments: the tags' ground truth, the board
    drawn on the ideal canvas (if it faces the camera), and the frame finished with the
    degradations ``deg`` or the ``camera`` model."""
    rows, cols, L, spacing_ratio, dic, first_id = grid
    R, t = pose.R, pose.t
    s = spacing_ratio * L
    ids = list(range(first_id, first_id + rows * cols))
    canvas, bg_name, k_ideal = _ideal_background(k, size, background, camera, gen)
    tags = aprilgrid_tag_corners(rows, cols, L, spacing_ratio=spacing_ratio)
    markers = _marker_truths(k, size, camera, [  # tag frame: the board's axes at the tag's centre
        (marker_id, Pose(R, R @ corners.mean(axis=0) + t), L)
        for marker_id, corners in zip(ids, tags, strict=True)
    ])
    if faces_camera(pose):
        outer, polys, weights = _board_polygons(dic, ids, rows, cols, L, s)
        _composite_exact(canvas, k_ideal, pose, outer, polys, weights, 1e-6 * L)
    params = {
        "background": bg_name,
        "rows": rows,
        "cols": cols,
        "tag_length": L,
        "spacing_ratio": spacing_ratio,
        "first_id": first_id,
        "board_rvec": [float(v) for v in pose.rvec],
        "board_tvec": [float(v) for v in t],
    }
    return _finish(canvas, k, k_ideal, size, markers, dic.name, params, camera, gen, **deg)


def _board_extent(rows: int, cols: int, L: float, s: float) -> FloatArray:
    """Board-frame corners (4, 3) of the printed area (margin included)."""
    pitch = L + s
    return np.c_[_rect(-2.0 * s, cols * pitch + s, 2.0 * s, -rows * pitch - s), np.zeros(4)]


def _place_board(rng: np.random.Generator, K: FloatArray, size: tuple[int, int],
                 n_ids: int) -> tuple[int, int, float, Pose]:
    """Random rows, cols, image tag side and pose of a board fully inside the image."""
    w, h = size
    f = K[0, 0]
    L, s = BOARD_TAG_LENGTH, BOARD_SPACING_RATIO * BOARD_TAG_LENGTH
    for _ in range(1000):
        rows, cols = (int(v) for v in rng.integers(3, 7, size=2))
        if rows * cols > n_ids:
            continue
        extent = _board_extent(rows, cols, L, s)
        diag = float(np.linalg.norm(extent[0] - extent[2])) / L  # board diagonal in tags
        lo = max(_TAG_FRACTION[0] * h, _MIN_TAG_PX)
        hi = min(_TAG_FRACTION[1] * h, (min(w, h) - 8.0) / diag)
        if hi < lo:
            continue
        tag_px = float(rng.uniform(lo, hi))
        depth = f * L / tag_px
        half = 0.5 * diag * tag_px
        if 2.0 * half + 10.0 > min(w, h):  # room for the centre draws below
            continue
        uv = np.array([rng.uniform(half + 4.0, w - 5.0 - half),
                       rng.uniform(half + 4.0, h - 5.0 - half)])
        ray = np.linalg.solve(K, np.array([uv[0], uv[1], 1.0]))
        facing = _rotation_to(ray / np.linalg.norm(ray)) @ np.diag([1.0, -1.0, -1.0])
        tilt_dir = rng.uniform(0.0, 2.0 * np.pi)
        tilt = Rotation.from_rotvec(rng.uniform(0.0, np.radians(_MAX_TILT_DEG))
                                    * np.array([np.cos(tilt_dir), np.sin(tilt_dir), 0.0]))
        spin = Rotation.from_rotvec([0.0, 0.0, rng.uniform(0.0, 2.0 * np.pi)])
        R = facing @ tilt.as_matrix() @ spin.as_matrix()
        centre = 0.5 * (extent[0] + extent[2])
        t = depth * ray - R @ centre  # the board's centre on the ray through uv
        pc = extent @ R.T + t
        if np.any(pc[:, 2] <= 0):
            continue
        quad = pc[:, :2] / pc[:, 2:3] * [K[0, 0], K[1, 1]] + [K[0, 2], K[1, 2]]
        if np.any(quad < 1.5) or np.any(quad > np.array([w, h]) - 2.5):
            continue
        return rows, cols, tag_px, Pose(R, t)
    raise RuntimeError(f"could not place an AprilGrid in a {w}x{h} image")  # pragma: no cover


def random_board_scene(
    rng: np.random.Generator | int,
    *,
    size: tuple[int, int] = (640, 480),
    dictionary: str | Dictionary = "DICT_APRILTAG_36h11",
    camera: bool | CameraEffects = True,
    difficulty: str = "easy",
    background: str | NDArray[np.uint8] | None = None,
) -> MarkerRender:
    """Render a random AprilGrid wholly inside the image.

    The camera is :func:`~visloc.synth.scenes.default_camera`. The board has 3-6 rows and
    3-6 columns of tags of side :data:`BOARD_TAG_LENGTH` with Kalibr's spacing ratio 0.3,
    consecutive ids from a random first id; a tag spans 6-12 % of the image height (at least
    20 px) when facing the camera, less when that would not let the board fit in the image
    in any in-plane rotation. The board is tilted up to 40 deg away from facing the camera and
    rotated in its plane at random; its printed area (margin included) lies at least 2 px
    inside the image.

    Parameters
    ----------
    rng : numpy.random.Generator or int
        Source of randomness (an int is a seed); the scene is a deterministic function of it.
    size : (int, int)
        ``(width, height)``.
    dictionary : str or Dictionary
        Tag dictionary (at least 9 markers; boards never hold more tags than it has).
    camera : bool or CameraEffects
        ``True``: random camera effects as :func:`~visloc.synth.scenes.random_scene` draws
        them for ``difficulty``; ``False``: its older degradations; a ``CameraEffects`` is
        used as given.
    difficulty : {'easy', 'hard'}
        Only the image degradations differ (see :func:`~visloc.synth.scenes.random_scene`).
    background : str, ndarray (H, W) uint8 or None
        ``None`` draws a texture name as :func:`~visloc.synth.scenes.random_scene` does.

    Returns
    -------
    MarkerRender
        As :func:`render_aprilgrid`; ``params`` also holds ``difficulty``.

    Raises
    ------
    TypeError, ValueError
        On a malformed argument; the message names it.
    """
    rng = check_rng(rng, allow_none=False)
    w, h = check_size(size)
    if min(w, h) < 160:
        raise ValueError(f"size must be at least (160, 160) for a board scene, got {(w, h)}")
    if difficulty not in BOARD_DIFFICULTIES:
        raise ValueError(f"difficulty must be one of {BOARD_DIFFICULTIES}, got {difficulty!r}")
    if not isinstance(camera, (bool, np.bool_, CameraEffects)):
        raise TypeError(f"camera must be a bool or a CameraEffects, got {type(camera).__name__}")
    dic = load_dictionary(dictionary)
    if len(dic) < 9:
        raise ValueError(f"dictionary must hold at least 9 markers, {dic.name} has {len(dic)}")
    K = default_camera((w, h))
    rows, cols, _, pose = _place_board(rng, K, (w, h), len(dic))
    first_id = int(rng.integers(0, len(dic) - rows * cols + 1))
    if background is None:
        choices = TEXTURES if difficulty == "easy" else tuple(t for t in TEXTURES if t != "flat")
        background = str(rng.choice(choices))
    if isinstance(camera, CameraEffects):
        deg: dict = {"camera": camera}
    elif camera:
        deg = {"camera": _camera_effects(rng, difficulty, K, (w, h))}
    else:
        deg = _degradations(rng, difficulty)
    render = render_aprilgrid(K, (w, h), pose, rows=rows, cols=cols, tag_length=BOARD_TAG_LENGTH,
                              spacing_ratio=BOARD_SPACING_RATIO, dictionary=dic,
                              first_id=first_id, background=background, rng=rng, **deg)
    render.params["difficulty"] = difficulty
    return render

