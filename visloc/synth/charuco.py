"""Render ChArUco boards (:class:`visloc.boards.CharucoBoard`) with exact ground truth.

The board is drawn as :func:`visloc.synth.boards.render_aprilgrid` draws an AprilGrid (exact
pixel-area coverage of the projected print, then the degradations or the camera model), with a
white margin of half a square around the squares. The pose is OpenCV's board-to-camera
transform (board frame: origin at the top-left corner, x right, y down the board, z into it);
the truth is every chessboard corner's (distorted) projection and the markers' corners.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from visloc.boards.charuco import CharucoBoard
from visloc.markers.dictionary import load_dictionary
from visloc.synth import markers as _render
from visloc.synth._checks import check_camera, check_size
from visloc.synth.camera import CameraEffects, distort_points, monotonic_radius
from visloc.synth.markers import VISIBLE_MARGIN, MarkerRender, project_points
from visloc.types import Pose

__all__ = ["CharucoRender", "render_charuco"]

FloatArray = NDArray[np.float64]
_FLIP = np.diag([1.0, -1.0, -1.0])  # OpenCV's board frame (y down, z in) <-> the printed face's (y up, z out)


@dataclass(frozen=True, eq=False)
class CharucoRender:
    """A rendered view of a ChArUco board.

    Attributes
    ----------
    render : MarkerRender
        The image (``render.image``), its camera (``K``, ``dist``) and the markers' truth.
    corners : ndarray (C, 2)
        Every chessboard corner's image position, px (distorted with a camera model).
    visible : ndarray (C,) bool
        Whether each corner is in front of the camera, on the printed face's side, and at
        least ``VISIBLE_MARGIN`` px inside the image.
    pose : Pose
        Board-to-camera transform, OpenCV's board frame.
    """

    render: MarkerRender
    corners: FloatArray
    visible: NDArray[np.bool_]
    pose: Pose

    @property
    def image(self) -> NDArray[np.uint8]:
        """The rendered grey image (H, W) uint8."""
        return self.render.image


def render_charuco(K: FloatArray, size: tuple[int, int], pose: Pose, board: CharucoBoard, *,
                   camera: CameraEffects | None = None, rng: np.random.Generator | int | None = None,
                   blur_sigma: float = 0.0, noise_sigma: float = 0.0) -> CharucoRender:
    """Render a ChArUco board seen by a camera, with exact ground truth.

    Parameters
    ----------
    K : ndarray (3, 3)
        Camera matrix (the pinhole part), px.
    size : (int, int)
        ``(width, height)``, px.
    pose : Pose
        Board-to-camera transform (OpenCV's board frame, module docstring), board units (m).
    board : CharucoBoard
        The board.
    camera : CameraEffects or None
        A camera model (blur, noise, vignetting, lens distortion k1 k2, sRGB, JPEG); None: a
        linear render with the degradations below.
    rng : numpy.random.Generator, int or None
        Randomness for noise.
    blur_sigma, noise_sigma : float
        Degradations of a linear render (px, grey levels); 0 with ``camera``.

    Returns
    -------
    CharucoRender

    Raises
    ------
    TypeError, ValueError
        A malformed argument (the message names it).
    """
    if not isinstance(board, CharucoBoard):
        raise TypeError(f"board must be a CharucoBoard, got {type(board).__name__}")
    if not isinstance(pose, Pose):
        raise TypeError(f"pose must be a visloc.types.Pose, got {type(pose).__name__}")
    k = check_camera(K)
    w, h = check_size(size)
    deg, gen = _render._check_degradations(camera, rng, blur_sigma=blur_sigma, motion_blur=0.0, motion_angle=0.0,
                                   noise_sigma=noise_sigma, gain=1.0, gradient=0.0, jpeg_quality=None)
    dic = load_dictionary(board.dictionary)
    face = Pose(np.asarray(pose.R, float) @ _FLIP, np.asarray(pose.t, float))  # the printed face's frame
    canvas, _, k_ideal = _render._ideal_background(k, (w, h), None, camera, gen)
    s, L = board.square_length, board.marker_length
    centres = board.marker_corners.mean(axis=1) @ _FLIP  # face frame: y up
    markers = _render._marker_truths(k, (w, h), camera, [(int(mid), Pose(face.R, face.R @ c + face.t), L)
                                                         for mid, c in zip(board.marker_ids.tolist(), centres,
                                                                           strict=True)])
    facing = bool(np.dot(face.t, face.R[:, 2]) < 0.0)
    if facing:
        outer, polys, weights = _board_polygons(board, dic, centres)
        _render._composite_exact(canvas, k_ideal, face, outer, polys, weights, 1e-6 * s)
    corners, visible = _corner_truth(k, (w, h), camera, pose, board.chessboard_corners)
    params = {"board": {"squares_x": board.squares_x, "squares_y": board.squares_y, "square_length": s,
                        "marker_length": L, "dictionary": board.dictionary, "first_id": board.first_id,
                        "legacy": board.legacy},
              "board_rvec": [float(v) for v in pose.rvec], "board_tvec": [float(v) for v in pose.t]}
    rendered = _render._finish(canvas, k, k_ideal, (w, h), markers, dic.name, params, camera, gen, **deg)
    return CharucoRender(rendered, corners, visible & facing, pose)


def _board_polygons(board: CharucoBoard, dic, centres: FloatArray):
    """Face-frame polygons: the printed area (half a square of white margin) and the weighted
    polygons whose sum is 1 on white print (see ``_composite_exact``)."""
    s = board.square_length
    width, height = board.squares_x * s, board.squares_y * s
    m = 0.5 * s
    outer = np.array([[-m, m], [width + m, m], [width + m, -height - m], [-m, -height - m]])
    polys, weights = [outer], [1.0]
    for square in board.black_squares[0]:  # board frame (y down) -> the face's (y up)
        polys.append(square * (1.0, -1.0))
        weights.append(-1.0)
    for mid, centre in zip(board.marker_ids.tolist(), centres, strict=True):
        _, tag, tag_w = _render._plane_polygons(dic.bits[mid], board.marker_length, 0.0)
        polys.extend(p + centre[:2] for p in tag[1:])
        weights.extend(tag_w[1:])
    return outer, polys, weights


def _corner_truth(k: FloatArray, size: tuple[int, int], camera: CameraEffects | None, pose: Pose,
                  points: FloatArray) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Image positions (C, 2) of board points (C, 3) and whether each is visible."""
    w, h = size
    uv = project_points(k, pose, points)
    in_front = pose.apply(points)[:, 2] > 0
    if camera is not None:
        one_to_one = _render._within_radius(uv[:, None], k, monotonic_radius(camera.k1, camera.k2))
        uv = distort_points(uv, k, camera.k1, camera.k2)
        in_front &= one_to_one
    inside = np.isfinite(uv).all(axis=1) & (uv >= VISIBLE_MARGIN - 0.5).all(axis=1) & (
        uv[:, 0] <= w - 0.5 - VISIBLE_MARGIN) & (uv[:, 1] <= h - 0.5 - VISIBLE_MARGIN)
    return uv, in_front & inside
