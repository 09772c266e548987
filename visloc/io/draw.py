"""Drawing detected markers (outlines, corner 0, ids and pose axes) onto images."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from visloc.images import check_image
from visloc.types import MarkerDetection

__all__ = ["draw_markers"]

OUTLINE_COLOR = (0, 255, 0)
"""BGR colour of marker outlines."""
CORNER0_COLOR = (255, 0, 255)
"""BGR colour of the dot on each marker's corner 0 (its own top-left)."""
TEXT_COLOR = (255, 255, 255)
AXIS_COLORS = ((0, 0, 255), (0, 255, 0), (255, 0, 0))
"""BGR colours of the x (red), y (green) and z (blue) axes."""

_SHIFT = 4  # cv2 drawing with 4 fractional bits: 1/16 px resolution
_SCALE = 1 << _SHIFT
_LIMIT = 1e6  # clamp far-off projected points so fixed-point coordinates fit in int32


def _fixed(points: NDArray[np.float64]) -> NDArray[np.int32]:
    """Pixel coordinates (pixel centres at integers) to cv2 fixed-point with ``_SHIFT`` bits."""
    return np.round(np.clip(points, -_LIMIT, _LIMIT) * _SCALE).astype(np.int32)


def _pt(point: NDArray[np.float64]) -> tuple[int, int]:
    """One point as a cv2 fixed-point ``(x, y)`` tuple of Python ints."""
    x, y = _fixed(point)
    return int(x), int(y)


def _to_bgr(image: object) -> NDArray[np.uint8]:
    img = check_image(image, name="image")
    if img.ndim == 2:
        return cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    if img.shape[2] == 1:
        return cv2.cvtColor(img[:, :, 0], cv2.COLOR_GRAY2BGR)
    if img.shape[2] == 4:
        return np.ascontiguousarray(img[:, :, :3])
    return img.copy()


def _camera_matrices(camera: Any) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``camera.K`` as (3, 3) and ``camera.dist`` as a flat array (zeros when ``None``)."""
    if not hasattr(camera, "K"):
        raise TypeError(
            f"camera must have attributes K (3, 3) and dist (n,), got {type(camera).__name__}"
        )
    K = np.asarray(camera.K, dtype=np.float64)
    if K.shape != (3, 3) or not np.all(np.isfinite(K)):
        raise ValueError(f"camera.K must be a finite (3, 3) matrix, got shape {K.shape}")
    dist = getattr(camera, "dist", None)
    d = np.zeros(5) if dist is None else np.asarray(dist, dtype=np.float64).ravel()
    if d.size not in (4, 5, 8, 12, 14):
        raise ValueError(f"camera.dist must have 4, 5, 8, 12 or 14 values, got {d.size}")
    return K, d


def _pose_arrays(pose: Any, i: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    R = np.asarray(getattr(pose, "R", None), dtype=np.float64)
    t = np.asarray(getattr(pose, "t", None), dtype=np.float64).ravel()
    if R.shape != (3, 3) or t.shape != (3,):
        raise ValueError(
            f"poses[{i}] must have R (3, 3) and t (3,), got R {R.shape} and t {t.shape}"
        )
    return R, t


def check_pose_inputs(
    detections: Sequence[MarkerDetection],
    poses: Sequence[Any] | None,
    camera: Any,
    marker_length: float | None,
) -> None:
    """Check the optional pose arguments shared by the drawing and logging functions.

    Parameters
    ----------
    detections : sequence of MarkerDetection
        The markers drawn or logged.
    poses : sequence of (Pose or None), or None
        One entry per detection (None where a marker has no pose), or None: then nothing
        else is checked.
    camera : Camera or None
        Intrinsics the poses are drawn with (needed with ``poses``).
    marker_length : float or None
        Marker side, m (finite and > 0; needed with ``poses``).

    Raises
    ------
    ValueError
        If ``poses`` does not match ``detections`` in length, or ``camera`` /
        ``marker_length`` is missing or invalid while ``poses`` is given.
    """
    if poses is None:
        return
    if len(poses) != len(detections):
        raise ValueError(
            f"poses must have one entry (or None) per detection: "
            f"got {len(poses)} poses for {len(detections)} detections"
        )
    if camera is None:
        raise ValueError("camera is required when poses are given")
    if marker_length is None:
        raise ValueError("marker_length is required when poses are given")
    if not np.isfinite(marker_length) or marker_length <= 0:
        raise ValueError(f"marker_length must be a positive finite length, got {marker_length!r}")


def _corners(det: MarkerDetection, i: int) -> NDArray[np.float64]:
    c = np.asarray(det.corners, dtype=np.float64)
    if c.shape != (4, 2):
        raise ValueError(f"detections[{i}].corners must have shape (4, 2), got {c.shape}")
    return c


def _draw_outlines(out: NDArray[np.uint8], detections: list[MarkerDetection], thickness: int) -> None:
    """Draw each marker's outline and the dot on its corner 0 into ``out`` (BGR, in place),
    checking the corners (4, 2) of each detection."""
    for i, det in enumerate(detections):
        corners = _corners(det, i)
        cv2.polylines(out, [_fixed(corners)], True, OUTLINE_COLOR, thickness, cv2.LINE_AA, _SHIFT)
        radius = round(max(2.0, 2.0 * thickness) * _SCALE)
        cv2.circle(out, _pt(corners[0]), radius, CORNER0_COLOR, -1, cv2.LINE_AA, _SHIFT)


def _draw_axes(
    out: NDArray[np.uint8], poses: list[Any], camera: Any, marker_length: float, thickness: int
) -> None:
    """Draw the projected x, y, z axes (``marker_length / 2`` long, in the units of ``t``) of
    each pose into ``out`` (BGR, in place); None poses, poses with an axis point behind the
    camera and projections that are not finite are skipped."""
    K, dist = _camera_matrices(camera)
    half = 0.5 * float(marker_length)
    axis_points = np.array([[0, 0, 0], [half, 0, 0], [0, half, 0], [0, 0, half]], float)
    for i, pose in enumerate(poses):
        if pose is None:
            continue
        R, t = _pose_arrays(pose, i)
        if np.any((axis_points @ R.T + t)[:, 2] <= 1e-9):
            continue
        rvec, _ = cv2.Rodrigues(R)
        projected, _ = cv2.projectPoints(axis_points, rvec, t, K, dist)
        p = projected.reshape(-1, 2)
        if not np.all(np.isfinite(p)):
            continue
        origin = _pt(p[0])
        for k, color in enumerate(AXIS_COLORS):
            cv2.line(out, origin, _pt(p[k + 1]), color, thickness + 1, cv2.LINE_AA, _SHIFT)


def _draw_ids(
    out: NDArray[np.uint8], detections: list[MarkerDetection], font_scale: float, thickness: int
) -> None:
    """Write each marker's id, white on a dark outline, centred on its ``center`` (or the mean
    of its corners) into ``out`` (BGR, in place); markers without a finite centre get none."""
    for det in detections:
        text = str(int(det.id))
        (tw, th), _ = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, font_scale, thickness)
        center = getattr(det, "center", None)
        if center is None:
            center = np.asarray(det.corners, dtype=np.float64).mean(axis=0)
        cx, cy = np.asarray(center, dtype=np.float64)
        if not (np.isfinite(cx) and np.isfinite(cy)):
            continue
        org = (round(float(cx) - tw / 2), round(float(cy) + th / 2))
        cv2.putText(
            out,
            text,
            org,
            cv2.FONT_HERSHEY_SIMPLEX,
            font_scale,
            (0, 0, 0),
            thickness + 2,
            cv2.LINE_AA,
        )
        cv2.putText(
            out, text, org, cv2.FONT_HERSHEY_SIMPLEX, font_scale, TEXT_COLOR, thickness, cv2.LINE_AA
        )


def draw_markers(
    image: NDArray[np.uint8],
    detections: Sequence[MarkerDetection],
    *,
    poses: Sequence[Any | None] | None = None,
    camera: Any | None = None,
    marker_length: float | None = None,
) -> NDArray[np.uint8]:
    """Draw detected markers, and optionally their pose axes, on a copy of an image.

    Each marker gets an anti-aliased outline drawn with sub-pixel accuracy (``cv2`` fixed
    point, ``shift=4``), a dot on corner 0 (the marker's own top-left) and its id at the centre.
    With ``poses``, the marker's axes are projected through the camera: x red, y green,
    z blue (out of the marker face), each ``marker_length / 2`` long. Axes of a pose with any
    axis point behind the camera are not drawn.

    Parameters
    ----------
    image : ndarray (H, W) or (H, W, 3) uint8
        Grey or BGR image (BGRA is accepted, alpha dropped); it is not modified.
    detections : sequence of MarkerDetection
        Markers to draw (anything with ``id`` and ``corners`` (4, 2): ``(x, y)`` px, pixel
        centres at integer coordinates, corner 0 the marker's own top-left).
    poses : sequence of Pose or None, optional
        One entry per detection (``None`` for markers without a pose); anything with ``R``
        (3, 3) and ``t`` (3,) mapping marker points into the camera frame.
    camera : object, optional
        Required with ``poses``: has ``K`` (3, 3) and ``dist`` (n,) (or ``dist=None``).
    marker_length : float, optional
        Required with ``poses``: marker side in the units of ``t`` (metres).

    Returns
    -------
    ndarray (H, W, 3) uint8
        A new BGR image with the annotations.

    Raises
    ------
    TypeError
        If ``image`` is not a uint8 array or ``camera`` lacks ``K``.
    ValueError
        If shapes are wrong or ``poses`` is given without ``camera`` / ``marker_length`` or
        with a different length than ``detections``.
    """
    out = _to_bgr(image)
    detections = list(detections)
    poses = None if poses is None else list(poses)
    check_pose_inputs(detections, poses, camera, marker_length)
    h, w = out.shape[:2]
    thickness = max(1, round(min(h, w) / 400))
    font_scale = max(0.4, min(h, w) / 900)
    _draw_outlines(out, detections, thickness)
    if poses is not None:
        _draw_axes(out, poses, camera, marker_length, thickness)  # type: ignore[arg-type]
    _draw_ids(out, detections, font_scale, thickness)
    return out
