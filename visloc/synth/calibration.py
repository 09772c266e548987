"""Camera-like views of a ChArUco board at varied poses, with the true camera: data for
``visloc calibrate`` and ``bench/calibrate.py``."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from visloc._checks import check_int
from visloc.boards.charuco import CharucoBoard
from visloc.pose.maps import MarkerMap
from visloc.synth.camera import CameraEffects
from visloc.synth.charuco import CharucoRender, render_charuco
from visloc.synth.datasets import write_camera_yml
from visloc.synth.grid import MapView, render_map_view
from visloc.synth.scenes import default_camera
from visloc.types import Pose

__all__ = ["CALIBRATION_CAMERA", "calibration_views", "marker_map_views", "render_calibration_views"]

#: The camera of the calibration views: optics blur, shot and read noise, vignetting, radial
#: distortion k1 = -0.12, k2 = 0.03, the sRGB curve, JPEG at quality 92
CALIBRATION_CAMERA = CameraEffects(blur_sigma=0.8, full_well=5000.0, read_noise=1.5, vignetting=0.25, k1=-0.12,
                                   k2=0.03, jpeg_quality=92)


def calibration_views(board: CharucoBoard, n: int, *, size: tuple[int, int] = (1280, 720), seed: int = 0,
                      camera: CameraEffects = CALIBRATION_CAMERA, hfov_deg: float = 70.0) -> list[CharucoRender]:
    """``n`` views of ``board`` at random poses that a careful calibration would take.

    Each view puts the board's centre at a random point of the image's central 70 %, at a
    distance where the board spans 45-85 % of the image width, tilted up to 45 degrees about
    a random axis in its plane and turned up to 30 degrees in it; views where fewer than half
    the board's corners are visible are drawn again.

    Parameters
    ----------
    board : CharucoBoard
        The board.
    n : int
        Number of views (1-500).
    size : (int, int)
        ``(width, height)``, px.
    seed : int
        Seeds the poses and the noise (>= 0).
    camera : CameraEffects
        The camera model (its k1, k2 are the true distortion).
    hfov_deg : float
        Horizontal field of view of the pinhole part, degrees.

    Returns
    -------
    list of CharucoRender
        Each with its image, the true ``K`` and ``dist`` (``render.K``, ``render.dist``) and
        the corners' truth.

    Raises
    ------
    TypeError, ValueError
        ``n`` not an integer in [1, 500]; ``seed`` not an integer >= 0 (the message names it).
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 1 <= n <= 500:
        raise ValueError(f"n must be an integer in [1, 500], got {n!r}")
    w, h = size
    K = default_camera((w, h), hfov_deg=hfov_deg)
    rng = np.random.default_rng(check_int(seed, "seed", low=0))
    width = board.squares_x * board.square_length
    centre = np.array([0.5 * width, 0.5 * board.squares_y * board.square_length, 0.0])
    out: list[CharucoRender] = []
    for _ in range(100 * n):
        if len(out) == n:
            break
        view = render_charuco(K, (w, h), _board_pose(rng, K, (w, h), centre, width), board, camera=camera, rng=rng)
        if view.visible.sum() >= 0.5 * len(view.visible):
            out.append(view)
    if len(out) < n:
        raise ValueError(f"could not place {n} views of the board in a {w}x{h} image")
    return out


def _board_pose(rng: np.random.Generator, K: np.ndarray, size: tuple[int, int], centre: np.ndarray, width: float,
                facing: Rotation | None = None) -> Pose:
    """A random calibration pose (:func:`calibration_views`): the board's ``centre`` at a point
    of the image's central 70 %, spanning 45-85 % of its width, tilted up to 45 degrees and
    turned up to 30; ``facing`` turns the board's own axes first (a map with z up is seen
    from above with a half turn about x)."""
    w, h = size
    axis = rng.normal(size=2)
    tilt = Rotation.from_rotvec(np.r_[axis / np.linalg.norm(axis), 0.0] * np.radians(rng.uniform(0, 45)))
    spin = Rotation.from_rotvec([0.0, 0.0, np.radians(rng.uniform(-30, 30))])
    R = (tilt * spin * facing).as_matrix() if facing is not None else (tilt * spin).as_matrix()
    depth = K[0, 0] * width / (rng.uniform(0.45, 0.85) * w)
    ray = np.linalg.solve(K, [rng.uniform(0.15 * w, 0.85 * w), rng.uniform(0.15 * h, 0.85 * h), 1.0])
    return Pose(R, ray * depth - R @ centre)


def marker_map_views(marker_map: MarkerMap, dictionary: str, n: int, *, size: tuple[int, int] = (1280, 720),
                     seed: int = 0, camera: CameraEffects = CALIBRATION_CAMERA, hfov_deg: float = 70.0,
                     min_markers: float = 0.5) -> list[MapView]:
    """``n`` camera-like views of a planar marker map (a printed ``GridMap``) at the poses of
    :func:`calibration_views`, seen from above: calibration data for :class:`visloc.boards.
    MarkerBoard`.

    Parameters
    ----------
    marker_map : MarkerMap
        Markers in the map's ``z = 0`` plane (z up).
    dictionary : str
        Their dictionary.
    n, size, seed, camera, hfov_deg
        As :func:`calibration_views`.
    min_markers : float
        Views where fewer than this share of the markers is visible are drawn again.

    Returns
    -------
    list of MapView
        Each with its image and per-marker truth (``view.render``) and the pose; the true
        ``K`` is ``view.render.K``.
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 1 <= n <= 500:
        raise ValueError(f"n must be an integer in [1, 500], got {n!r}")
    w, h = size
    K = default_camera((w, h), hfov_deg=hfov_deg)
    rng = np.random.default_rng(check_int(seed, "seed", low=0))
    pts = np.concatenate([marker_map.corners_of(int(i)) for i in marker_map.ids])
    centre, width = 0.5 * (pts.min(axis=0) + pts.max(axis=0)), float(np.ptp(pts[:, 0]))
    from_above = Rotation.from_euler("x", 180.0, degrees=True)
    out: list[MapView] = []
    for _ in range(100 * n):
        if len(out) == n:
            break
        view = render_map_view(marker_map, K, (w, h), _board_pose(rng, K, (w, h), centre, width, from_above),
                               dictionary, camera=camera, rng=rng)
        if sum(m.visible for m in view.render.markers) >= min_markers * len(marker_map.ids):
            out.append(view)
    if len(out) < n:
        raise ValueError(f"could not place {n} views of the map in a {w}x{h} image")
    return out


def render_calibration_views(outdir: str | Path, board: CharucoBoard, *, n: int = 30,
                             size: tuple[int, int] = (1280, 720), seed: int = 0) -> list[Path]:
    """Write :func:`calibration_views` to ``outdir``: ``view_000.png`` ..., the true camera
    ``camera_truth.yml`` and ``ground_truth.json`` (per view its file, the board pose and
    every visible corner's id and position, px).

    Parameters
    ----------
    outdir : str or Path
        Output folder (created).
    board : CharucoBoard
        The board.
    n : int
        Number of views.
    size : (int, int)
        ``(width, height)``, px.
    seed : int
        Seeds poses and noise.

    Returns
    -------
    list of Path
        The view images written.
    """
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    views = calibration_views(board, n, size=size, seed=seed)
    paths, records = [], []
    for k, view in enumerate(views):
        p = outdir / f"view_{k:03d}.png"
        cv2.imwrite(str(p), view.image)
        paths.append(p)
        ids = np.flatnonzero(view.visible)
        records.append({"file": p.name, "board_rvec": view.pose.rvec.tolist(), "board_tvec": view.pose.t.tolist(),
                        "corner_ids": ids.tolist(), "corners": view.corners[ids].round(4).tolist()})
    write_camera_yml(outdir / "camera_truth.yml", views[0].render.K, size, views[0].render.dist)
    (outdir / "ground_truth.json").write_text(json.dumps({"size": list(size), "views": records}, indent=1))
    return paths
