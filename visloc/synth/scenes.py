"""Random marker scenes of graded difficulty, for accuracy tests and benchmarks."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from visloc._checks import check_int
from visloc.markers.dictionary import Dictionary, load_dictionary
from visloc.synth._checks import check_number, check_rng, check_size
from visloc.synth.camera import CameraEffects
from visloc.synth.markers import MarkerRender, render_markers
from visloc.synth.textures import TEXTURES
from visloc.types import Pose

FloatArray = NDArray[np.float64]

#: Difficulty levels of :func:`random_scene`.
DIFFICULTIES = ("easy", "hard", "small", "empty", "dark")
#: Side (m) of the black square of every marker in random scenes.
MARKER_LENGTH = 0.15
#: Quiet zone (cells) of markers in random scenes.
MARGIN_CELLS = 1.0

# Marker side in the image as a fraction of the image height, and largest tilt (deg).
_SIZE = {"easy": (0.20, 0.35), "hard": (0.12, 0.25), "small": (0.035, 0.08), "dark": (0.20, 0.35)}
_TILT = {"easy": 40.0, "hard": 50.0, "small": 50.0, "dark": 40.0}
# Normalised radius of the image corner of a 4:3 default camera: the lens distortion drawn for
# random scenes is scaled down for images whose corners lie farther out, so it never folds.
_CORNER_RADIUS = 0.8
#: Exposure range of 'dark' scenes rendered with a camera model (image mean below 30).
DARK_EXPOSURE = (0.015, 0.035)


def default_camera(size: tuple[int, int], *, hfov_deg: float = 65.0) -> FloatArray:
    """Pinhole matrix with square pixels, the principal point at the image centre and the
    given horizontal field of view.

    Parameters
    ----------
    size : (int, int)
        ``(width, height)``, px.
    hfov_deg : float
        Horizontal field of view in degrees, in (0, 180).

    Returns
    -------
    ndarray (3, 3) float64
        ``[[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]]``, ``f = (w / 2) / tan(hfov / 2)``
        px (pixel centres at integer coordinates).

    Raises
    ------
    TypeError, ValueError
        On a malformed argument; the message names it.
    """
    w, h = check_size(size)
    hfov = np.radians(check_number(hfov_deg, "hfov_deg", low=0.0, high=180.0, low_open=True,
                                   high_open=True))
    f = 0.5 * w / np.tan(0.5 * hfov)
    return np.array([[f, 0.0, 0.5 * (w - 1)], [0.0, f, 0.5 * (h - 1)], [0.0, 0.0, 1.0]])


def _rotation_to(d: FloatArray) -> FloatArray:
    """Smallest rotation taking the camera's optical axis (0, 0, 1) onto unit vector ``d``."""
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, d)
    s = np.linalg.norm(axis)
    if s < 1e-12:
        return np.eye(3)
    return Rotation.from_rotvec(axis / s * np.arctan2(s, float(d @ z))).as_matrix()


def _random_pose(rng: np.random.Generator, K: FloatArray, uv: FloatArray, depth: float,
                 max_tilt: float) -> Pose:
    """Marker centred on pixel ``uv`` at ``depth``, tilted up to ``max_tilt`` rad away from
    facing the camera, rotated in its plane at random."""
    ray = np.linalg.solve(K, np.array([uv[0], uv[1], 1.0]))
    t = depth * ray
    facing = _rotation_to(ray / np.linalg.norm(ray)) @ np.diag([1.0, -1.0, -1.0])
    tilt_dir = rng.uniform(0.0, 2.0 * np.pi)
    tilt = Rotation.from_rotvec(
        rng.uniform(0.0, max_tilt) * np.array([np.cos(tilt_dir), np.sin(tilt_dir), 0.0])
    ).as_matrix()
    spin = Rotation.from_rotvec([0.0, 0.0, rng.uniform(0.0, 2.0 * np.pi)]).as_matrix()
    return Pose(facing @ tilt @ spin, t)


def _quads_overlap(a: FloatArray, b: FloatArray) -> bool:
    """Separating-axis test for two convex polygons (n, 2)."""
    for poly in (a, b):
        edges = np.roll(poly, -1, axis=0) - poly
        normals = np.c_[-edges[:, 1], edges[:, 0]]
        pa, pb = a @ normals.T, b @ normals.T
        if np.any((pa.max(axis=0) <= pb.min(axis=0)) | (pb.max(axis=0) <= pa.min(axis=0))):
            return False
    return True


def _outer_quad(K: FloatArray, pose: Pose, length: float, cells: int) -> FloatArray:
    """Image quad of the printed area (black square plus quiet zone)."""
    ho = 0.5 * length * (1.0 + 2.0 * MARGIN_CELLS / cells)
    pts = pose.apply(np.array([[-ho, ho, 0], [ho, ho, 0], [ho, -ho, 0], [-ho, -ho, 0]]))
    uv = pts @ K.T
    return uv[:, :2] / uv[:, 2:3]


def _place(rng: np.random.Generator, K: FloatArray, size: tuple[int, int], n: int,
           dic: Dictionary, difficulty: str) -> list[tuple[int, Pose, float]]:
    w, h = size
    lo, hi = _SIZE[difficulty]
    max_tilt = np.radians(_TILT[difficulty])
    cells = dic.marker_size + 2
    f = K[0, 0]
    for _ in range(50):
        ids = rng.choice(len(dic), size=n, replace=False)
        quads: list[FloatArray] = []
        out = []
        for marker_id in ids:
            for _ in range(200):
                side_px = rng.uniform(lo, hi) * h
                depth = f * MARKER_LENGTH / side_px
                half = 0.5 * side_px * (1.0 + 2.0 * MARGIN_CELLS / cells)
                if 2 * half + 6 >= min(w, h):
                    continue
                uv = np.array([rng.uniform(half + 2, w - 3 - half), rng.uniform(half + 2, h - 3 - half)])
                pose = _random_pose(rng, K, uv, depth, max_tilt)
                quad = _outer_quad(K, pose, MARKER_LENGTH, cells)
                if np.any(quad < 1.5) or np.any(quad > np.array([w, h]) - 2.5):
                    continue
                if any(_quads_overlap(quad, q) for q in quads):
                    continue
                quads.append(quad)
                out.append((int(marker_id), pose, MARKER_LENGTH))
                break
            else:
                break
        if len(out) == n:
            return out
    raise RuntimeError(f"could not place {n} non-overlapping markers in a {w}x{h} image")


def _hard_blur(rng: np.random.Generator, p: dict) -> NDArray[np.bool_]:
    """The degradations of a hard frame: which of six kinds apply (at least one), with the
    first two (optical blur, motion blur) drawn into ``p``; the caller draws the others."""
    kinds = rng.random(6) < 0.5
    if not kinds.any():
        kinds[rng.integers(6)] = True
    if kinds[0]:
        p["blur_sigma"] = float(rng.uniform(1.0, 2.5))
    if kinds[1]:
        p["motion_blur"] = float(rng.uniform(3.0, 8.0))
        p["motion_angle"] = float(rng.uniform(0.0, np.pi))
    return kinds


def _degradations(rng: np.random.Generator, difficulty: str) -> dict:
    p = {"blur_sigma": float(rng.uniform(0.3, 0.8)), "noise_sigma": float(rng.uniform(0.0, 2.0))}
    if difficulty == "dark":  # image mean below 30: gain * 255 + noise bias < 27
        p["noise_sigma"] = float(rng.uniform(1.0, 3.0))
        p["gain"] = float(rng.uniform(0.04, 0.1))
        return p
    if difficulty != "hard":
        return p
    kinds = _hard_blur(rng, p)
    if kinds[2]:
        p["noise_sigma"] = float(rng.uniform(4.0, 10.0))
    if kinds[3]:
        p["gain"] = float(rng.uniform(0.25, 0.5))
    if kinds[4]:
        p["gradient"] = float(rng.uniform(0.3, 0.6))
    if kinds[5]:
        p["jpeg_quality"] = int(rng.integers(60, 81))
    return p


def _camera_effects(rng: np.random.Generator, difficulty: str, K: FloatArray,
                    size: tuple[int, int]) -> CameraEffects:
    """Random camera effects of a scene of the given difficulty (see :func:`random_scene`)."""
    w, h = size
    corner = np.hypot(max(K[0, 2], w - 1 - K[0, 2]) / K[0, 0],
                      max(K[1, 2], h - 1 - K[1, 2]) / K[1, 1])
    shrink = min(1.0, (_CORNER_RADIUS / corner) ** 2)
    p = {
        "blur_sigma": float(rng.uniform(0.5, 1.0)),
        "full_well": float(rng.uniform(3000.0, 8000.0)),
        "read_noise": float(rng.uniform(0.5, 2.0)),
        "vignetting": float(rng.uniform(0.0, 0.3)),
        "k1": float(rng.uniform(-0.15, 0.05)) * shrink,
        "k2": float(rng.uniform(-0.02, 0.02)) * shrink**2,
        "exposure": float(rng.uniform(0.8, 1.2)),
        "srgb": True,
    }
    jpeg = int(rng.integers(85, 96))
    p["jpeg_quality"] = jpeg if rng.random() < 0.5 else None
    if difficulty == "dark":
        p["exposure"] = float(rng.uniform(DARK_EXPOSURE[0], DARK_EXPOSURE[1]))
        p["read_noise"] = float(rng.uniform(1.0, 3.0))
    elif difficulty == "hard":
        kinds = _hard_blur(rng, p)
        if kinds[2]:
            p["read_noise"] = float(rng.uniform(3.0, 6.0))
            p["full_well"] = float(rng.uniform(1000.0, 3000.0))
        if kinds[3]:
            p["exposure"] = float(rng.uniform(0.25, 0.5))
        if kinds[4]:
            p["jpeg_quality"] = int(rng.integers(60, 81))
        if kinds[5]:
            p["vignetting"] = float(rng.uniform(0.3, 0.6))
    return CameraEffects(**p)


def random_scene(
    rng: np.random.Generator | int,
    *,
    size: tuple[int, int] = (640, 480),
    dictionary: str | Dictionary = "DICT_4X4_50",
    difficulty: str = "easy",
    n_markers: int | None = None,
    background: str | NDArray[np.uint8] | None = None,
    camera: bool | CameraEffects = False,
    lens: tuple[float, float] | None = None,
) -> MarkerRender:
    """Render a random scene of fully visible, non-overlapping markers.

    The camera is :func:`default_camera` (65 deg horizontal field of view). Every marker has
    side :data:`MARKER_LENGTH` and a one-cell quiet zone, a distinct random id, a random
    in-plane rotation and a tilt away from facing the camera; its printed area lies at least
    2 px inside the image and overlaps no other.

    Parameters
    ----------
    rng : numpy.random.Generator or int
        Source of randomness (an int is a seed); the scene is a deterministic function of it.
    size : (int, int)
        ``(width, height)``, px.
    dictionary : str or Dictionary
        Marker dictionary.
    difficulty : {'easy', 'hard', 'small', 'empty', 'dark'}
        ``'easy'``: marker side 20-35 % of the image height, tilt <= 40 deg, clean (blur
        sigma 0.3-0.8 px, noise 0-2). ``'hard'``: 12-25 %, tilt <= 50 deg, and at least one
        of blur sigma 1-2.5 px, motion blur 3-8 px, noise 4-10, gain 0.25-0.5, gradient
        0.3-0.6, JPEG quality 60-80. ``'small'``: 3.5-8 % (about 17-38 px at 480 rows),
        tilt <= 50 deg, clean. ``'empty'``: no marker, textured background, clean.
        ``'dark'``: markers as ``'easy'``, image mean grey level below 30 (gain 0.04-0.1,
        noise 1-3).
    n_markers : int or None
        Number of markers; ``None`` draws 1 to 4 (0 for ``'empty'``).
    background : str, ndarray or None
        As in :func:`render_markers`; ``None`` picks a random texture (``'flat'`` included
        only for ``'easy'`` and ``'dark'``).
    camera : bool or CameraEffects
        ``False`` (default): the degradations above, applied to the grey levels. ``True``:
        the image goes through a random camera model instead
        (:class:`~visloc.synth.camera.CameraEffects`, drawn after everything else, so the
        markers and background are those of ``camera=False``): optics blur sigma 0.5-1 px,
        shot noise (full well 3000-8000), read noise 0.5-2 linear grey levels, vignetting
        0-0.3, ``k1`` in [-0.15, 0.05], ``|k2|`` <= 0.02 (both scaled down for images whose
        corners lie farther out than a 4:3 image's), exposure 0.8-1.2, sRGB, JPEG quality
        85-95 half of the time. ``'hard'`` adds at least one of optics blur 1-2.5 px, motion
        blur 3-8 px, read noise 3-6 with full well 1000-3000, exposure 0.25-0.5, JPEG 60-80,
        vignetting 0.3-0.6; ``'dark'`` has exposure in :data:`DARK_EXPOSURE` and read noise
        1-3. A ``CameraEffects`` is used as given.
    lens : (float, float) or None
        With ``camera=True``: the distortion ``(k1, k2)`` to use instead of a random one
        (one lens for a whole data set).

    Returns
    -------
    MarkerRender
        ``params`` also holds ``difficulty``; with a camera model the ground truth is
        distorted and ``dist`` holds the distortion (see :func:`render_markers`).

    Raises
    ------
    TypeError
        A malformed ``rng``, ``size``, ``dictionary``, ``camera`` or ``n_markers``.
    ValueError
        Unknown ``difficulty`` or ``dictionary``, bad ``n_markers`` or ``size``.
    RuntimeError
        Markers that cannot be placed.
    """
    rng, (w, h), dic = _check_scene_args(rng, size, difficulty, camera, dictionary)
    n = _marker_count(rng, n_markers, difficulty, dic)
    K = default_camera((w, h))
    placements = _place(rng, K, (w, h), n, dic, difficulty) if n else []
    background = _scene_background(rng, background, flat=difficulty in ("easy", "dark"))
    deg = _scene_degradations(rng, camera, lens, difficulty, K, (w, h))
    render = render_markers(K, (w, h), placements, dic, background=background,
                            margin_cells=MARGIN_CELLS, rng=rng, **deg)
    render.params["difficulty"] = difficulty
    return render


def _check_scene_args(rng: object, size: object, difficulty: object, camera: object,
                      dictionary: str | Dictionary
                      ) -> tuple[np.random.Generator, tuple[int, int], Dictionary]:
    """:func:`random_scene`'s ``rng``, ``size``, ``difficulty``, ``camera`` and ``dictionary``
    checked in that order; returns the generator, ``(width, height)`` and the dictionary."""
    rng = check_rng(rng, allow_none=False)
    w, h = check_size(size)
    if difficulty not in DIFFICULTIES:
        raise ValueError(f"difficulty must be one of {DIFFICULTIES}, got {difficulty!r}")
    if not isinstance(camera, (bool, np.bool_, CameraEffects)):
        raise TypeError(f"camera must be a bool or a CameraEffects, got {type(camera).__name__}")
    return rng, (w, h), load_dictionary(dictionary)


def _marker_count(rng: np.random.Generator, n_markers: object, difficulty: str,
                  dic: Dictionary) -> int:
    """The number of markers of a random scene: ``n_markers`` checked, or if None drawn from
    1 to 4 (0 for ``'empty'``)."""
    if n_markers is None:
        return 0 if difficulty == "empty" else int(rng.integers(1, 5))
    n = check_int(n_markers, "n_markers", low=0, high=min(len(dic), 16))
    if difficulty == "empty" and n:
        raise ValueError(f"n_markers must be 0 or None for difficulty 'empty', got {n}")
    return n


def _scene_background(rng: np.random.Generator, background: str | NDArray[np.uint8] | None, *,
                      flat: bool) -> str | NDArray[np.uint8]:
    """``background`` as given, or if None a random texture name (``'flat'`` among the
    choices only if ``flat``)."""
    if background is not None:
        return background
    choices = TEXTURES if flat else tuple(t for t in TEXTURES if t != "flat")
    return str(rng.choice(choices))


def _scene_degradations(rng: np.random.Generator, camera: bool | CameraEffects,
                        lens: tuple[float, float] | None, difficulty: str, K: FloatArray,
                        size: tuple[int, int]) -> dict:
    """The image degradations of a random scene, as keyword arguments of
    :func:`render_markers`: ``camera`` as given, a random camera model (with ``lens`` as its
    distortion if given), or random degradations of the grey levels."""
    if isinstance(camera, CameraEffects):
        return {"camera": camera}
    if camera:
        effects = _camera_effects(rng, difficulty, K, size)
        if lens is not None:  # one lens for a whole data set
            effects = replace(effects, k1=float(lens[0]), k2=float(lens[1]))
        return {"camera": effects}
    return _degradations(rng, difficulty)
