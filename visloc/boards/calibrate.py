"""Camera calibration from a board's corners in several views: ``cv2.calibrateCamera``.

The solver is OpenCV's (``calibrateCameraExtended``: Levenberg-Marquardt over the intrinsics,
the distortion and every view's pose, started from Zhang's closed form; ``cv2.fisheye.calibrate``
for the fisheye model); visloc brings the
corners (:func:`visloc.boards.detect_charuco`) and the bookkeeping: views with too few corners
are left out, and the result carries the RMS reprojection error, each view's error and the
parameters' standard deviations, written into the camera file ``Camera.from_file`` reads.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from visloc.boards.charuco import CharucoBoard, CharucoCorners
from visloc.pose.camera import Camera

__all__ = ["CALIBRATION_MODELS", "Calibration", "calibrate"]

FloatArray = NDArray[np.float64]

#: Distortion models: name -> solver flags. ``pinhole-k1k2``: two radial terms;
#: ``k1k2p1p2k3``: OpenCV's default five; ``rational``: eight (k4-k6 in the denominator)
#: (``cv2.calibrateCamera``); ``fisheye``: ``cv2.fisheye``'s equidistant model with four
#: coefficients (``cv2.fisheye.calibrate``), for lenses of 120 degrees and more.
CALIBRATION_MODELS = {
    "pinhole-k1k2": cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST,
    "k1k2p1p2k3": 0,
    "rational": cv2.CALIB_RATIONAL_MODEL,
    "fisheye": cv2.CALIB_RECOMPUTE_EXTRINSIC | cv2.CALIB_FIX_SKEW,  # OpenCV 5: one set of flags
}
_FISHEYE_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)


@dataclass(frozen=True, eq=False)
class Calibration:
    """A calibrated camera.

    Attributes
    ----------
    K : ndarray (3, 3)
        Camera matrix, px (pixel centres at integer coordinates).
    dist : ndarray (n,)
        OpenCV distortion coefficients (k1, k2, p1, p2, k3[, k4, k5, k6]; the fisheye model's
        k1-k4).
    size : (int, int)
        ``(width, height)`` of the images, px.
    rms : float
        RMS reprojection error over all corners of the views used, px.
    per_view : ndarray (V,)
        Each used view's RMS reprojection error, px.
    std : ndarray (4 + n,)
        Standard deviations of fx, fy, cx, cy (px) and the distortion coefficients (NaN for
        the fisheye model: ``cv2.fisheye.calibrate`` gives none).
    views : list of int
        Indices of the views used (into the list given to :func:`calibrate`).
    model : str
        The distortion model (:data:`CALIBRATION_MODELS`).
    rvecs, tvecs : ndarray (V, 3)
        Each used view's board-to-camera rotation vector and translation (board units).
    """

    K: FloatArray
    dist: FloatArray
    size: tuple[int, int]
    rms: float
    per_view: FloatArray
    std: FloatArray
    views: list[int]
    model: str
    rvecs: FloatArray
    tvecs: FloatArray

    @property
    def camera(self) -> Camera:
        """The calibrated :class:`~visloc.pose.camera.Camera` (fisheye for the fisheye model)."""
        return Camera(self.K, self.dist, size=self.size, model="fisheye" if self.model == "fisheye" else "pinhole")

    def project(self, points: NDArray, view: int) -> FloatArray:
        """Pixels (N, 2) of board points (N, 3) in the ``view``-th used view (its solved pose).

        Parameters
        ----------
        points : array_like (N, 3) or (3,)
            Points in the board's frame, board units (those of ``chessboard_corners``); one
            point (3,) gives one row.
        view : int
            Index into the used views (:attr:`rvecs`, :attr:`tvecs`, :attr:`per_view`), not
            into the list given to :func:`calibrate` (``views[view]`` is that one's index).

        Returns
        -------
        ndarray (N, 2) float64
            Their pixels under ``K`` and ``dist`` (the model's projection, distortion
            included); points behind the camera give meaningless pixels.
        """
        R = cv2.Rodrigues(np.asarray(self.rvecs[view], np.float64))[0]
        return self.camera.project(np.asarray(points, np.float64) @ R.T + self.tvecs[view])

    def to_file(self, path: str | Path) -> Path:
        """Write the camera file (OpenCV FileStorage YAML, as ``Camera.from_file`` reads it)
        with the calibration's figures (the standard deviations only where they are known: not
        for the fisheye model).

        Parameters
        ----------
        path : str or Path
            Output file.

        Returns
        -------
        Path
        """
        path = Path(path)
        extra = {"distortion_model": self.model, "reprojection_rms_px": float(self.rms),
                 "per_view_rms_px": np.asarray(self.per_view, np.float64).reshape(1, -1),
                 "views_used": len(self.views)}
        if np.isfinite(self.std).all():  # the fisheye model has none: no node rather than .nan
            extra["std_fx_fy_cx_cy_dist"] = np.asarray(self.std, np.float64).reshape(1, -1)
        self.camera.to_file(path, extra=extra)
        return path


def calibrate(views: list[CharucoCorners], board: CharucoBoard, size: tuple[int, int], *,
              model: str = "k1k2p1p2k3", min_corners: int = 6) -> Calibration:
    """Calibrate a camera from a board's corners in several views.

    Parameters
    ----------
    views : list of CharucoCorners
        The corners found in each image (:func:`visloc.boards.detect_charuco`).
    board : CharucoBoard
        The board.
    size : (int, int)
        ``(width, height)`` of the images, px.
    model : str
        Distortion model, a key of :data:`CALIBRATION_MODELS`.
    min_corners : int
        Views with fewer corners are left out (>= 6: a homography and some slack per view).

    Returns
    -------
    Calibration

    Raises
    ------
    TypeError
        A view whose corner ids are not integers.
    ValueError
        An unknown model, a bad size, a view with a corner id outside ``[0, number of the
        board's corners)`` (the message names the view's index and the ids), or fewer than 3
        views with ``min_corners`` corners.
    """
    if model not in CALIBRATION_MODELS:
        raise ValueError(f"model must be one of {sorted(CALIBRATION_MODELS)}, got {model!r}")
    if isinstance(min_corners, bool) or int(min_corners) != min_corners or min_corners < 6:
        raise ValueError(f"min_corners must be an integer >= 6, got {min_corners!r}")
    w, h = (int(v) for v in size)
    if w < 16 or h < 16:
        raise ValueError(f"size must be at least 16 x 16 px, got {size}")
    n_board = len(board.chessboard_corners)
    for i, v in enumerate(views):
        ids = np.asarray(v.ids)
        if ids.size and ids.dtype.kind not in "iu":
            raise TypeError(f"views[{i}]: corner ids must be integers, got {ids.dtype}")
        off = ids[(ids < 0) | (ids >= n_board)]
        if off.size:
            raise ValueError(f"views[{i}]: corner ids {off.tolist()} are not ids of the board's corners, "
                             f"[0, {n_board})")
    used = [i for i, v in enumerate(views) if len(v) >= min_corners]
    if len(used) < 3:
        raise ValueError(f"calibration needs at least 3 views with {min_corners} or more board corners; "
                         f"{len(used)} of {len(views)} have them")
    obj = [board.chessboard_corners[views[i].ids].astype(np.float32) for i in used]
    img = [views[i].corners.astype(np.float32).reshape(-1, 1, 2) for i in used]
    flags = CALIBRATION_MODELS[model]
    if model == "fisheye":
        return _fisheye(obj, img, (w, h), used, flags)
    rms, K, dist, rvecs, tvecs, std_in, _, per_view = cv2.calibrateCameraExtended(
        obj, img, (w, h), None, None, flags=flags)
    n = len(np.ravel(dist)) if model != "pinhole-k1k2" else 5
    return Calibration(np.asarray(K, np.float64), np.ravel(dist).astype(np.float64)[:n], (w, h), float(rms),
                       np.ravel(per_view).astype(np.float64), np.ravel(std_in).astype(np.float64)[: 4 + n], used,
                       model, np.array(rvecs, np.float64).reshape(-1, 3), np.array(tvecs, np.float64).reshape(-1, 3))


def _fisheye(obj: list[NDArray], img: list[NDArray], size: tuple[int, int], used: list[int],
             flags: int) -> Calibration:
    """``cv2.fisheye.calibrate`` on the views' corners; each view's RMS reprojection error from
    its solved pose (the solver gives no per-view errors nor standard deviations).

    The solver is started from the principal point at the image centre and a focal length of
    (longer side) / pi (an equidistant lens seeing 180 degrees across it), then of (longer
    side) / 2 and (longer side) / (pi / 2), the lowest RMS kept: from its own start it can
    wander off (negative focal lengths) on wide-angle views."""
    obj64 = [o.reshape(1, -1, 3).astype(np.float64) for o in obj]  # (1, N, 3): what the solver takes
    img64 = [i.reshape(1, -1, 2).astype(np.float64) for i in img]
    w, h = size
    best, error = None, "no start converged"
    for f0 in (max(w, h) / np.pi, max(w, h) / 2.0, max(w, h) / (np.pi / 2.0)):
        K0 = np.array([[f0, 0.0, (w - 1) / 2.0], [0.0, f0, (h - 1) / 2.0], [0.0, 0.0, 1.0]])
        try:
            found = cv2.fisheye.calibrate(obj64, img64, size, K0, np.zeros(4), flags=flags | cv2.CALIB_USE_INTRINSIC_GUESS,
                                          criteria=_FISHEYE_CRITERIA)
        except cv2.error as exc:
            error = str(exc).strip().splitlines()[-1]
            continue
        if found[1][0, 0] > 0 and found[1][1, 1] > 0 and np.isfinite(found[0]) and (best is None or found[0] < best[0]):
            best = found
    if best is None:
        raise ValueError(f"the fisheye calibration did not converge: {error}")
    rms, K, dist, rvecs, tvecs = best
    K, dist = np.asarray(K, np.float64), np.ravel(dist).astype(np.float64)
    per_view = []
    for o, i, r, t in zip(obj64, img64, rvecs, tvecs, strict=True):
        proj, _ = cv2.fisheye.projectPoints(o, r, t, K, dist)
        per_view.append(float(np.sqrt(np.mean(np.sum((proj - i) ** 2, axis=2)))))
    return Calibration(K, dist, size, float(rms), np.array(per_view), np.full(8, np.nan), used, "fisheye",
                       np.array(rvecs, np.float64).reshape(-1, 3), np.array(tvecs, np.float64).reshape(-1, 3))
