"""Camera pose from every visible marker of a map at once (report §3.2.2, "Aruco marker grid").

Report §3.2.2: "Once the markers are detected, the two dimensional marker corner locations
(image-points) are known, and the corresponding three dimensional (real-world points)
locations can be looked up in the on-board map. Then, a Gauss-Newton iteration optimization
method is used to find the parameterized projective map, describing the bottom camera location
in the scene ... The parameters ... correspond directly to the states [x y z phi theta psi]."

The start is the best single-marker pose (the marker whose own pose reprojects all map corners
best); Gauss-Newton / Levenberg-Marquardt then fits all corners jointly; markers whose corners
disagree with the rest are dropped and the fit repeated.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from statistics import median

import numpy as np
from numpy.typing import NDArray

from visloc._checks import all_finite
from visloc.pose.camera import Camera
from visloc.pose.gauss_newton import levenberg_marquardt, reprojection_rms
from visloc.pose.maps import MarkerMap
from visloc.pose.marker_pose import MIN_PIXEL_SIGMA
from visloc.pose.planar import planar_solutions
from visloc.pose.rotations import euler_to_matrix, matrix_to_euler
from visloc.types import MarkerDetection, Pose

__all__ = ["MapPose", "estimate_camera_pose", "markers_in_view"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class MapPose:
    """The camera's pose in a marker map.

    Attributes
    ----------
    pose : Pose
        ``T_cam_map``: ``p_cam = R @ p_map + t``, with ``covariance`` of its ``params``
        and ``reprojection_rms`` over the corners used.
    used : list of int
        Ids of the markers in the final fit.
    rejected : list of int
        Map markers seen but dropped: detected more than once (first), or inconsistent with
        the rest.
    unknown : list of int
        Ids seen that are not in the map (ignored).
    residuals : dict of int -> float
        RMS reprojection error (px) of each marker seen in the map under the final pose.
    """

    pose: Pose
    used: list[int]
    rejected: list[int]
    unknown: list[int]
    residuals: dict[int, float]

    @property
    def position(self) -> FloatArray:
        """Camera centre in the map frame, m: ``-R^T t``."""
        return -self.pose.R.T @ self.pose.t

    @property
    def position_covariance(self) -> FloatArray | None:
        """(3, 3) covariance of :attr:`position`, m^2, propagated from ``pose.covariance``
        (the parameters ``[tx ty tz phi theta psi]`` of ``T_cam_map``) through
        ``c = -R(phi, theta, psi)^T t``; None when the pose has no covariance."""
        cov = self.pose.covariance
        if cov is None:
            return None
        R = self.pose.R
        u = R.T @ self.pose.t  # -c
        # d R / d angle_i = R [a_i]x with a_phi = e1, a_theta = Rx(phi)^T e2, a_psi = R^T e3, so
        # d c / d angle_i = a_i x u (phi from R's last row: Rx(phi)^T e2 = (0, cos phi, -sin phi);
        # at pitch +-90 deg phi is 0, as matrix_to_euler gives it)
        r20, r21, r22 = R[2].tolist()
        norm = math.hypot(r21, r22)
        cos_phi, sin_phi = (r22 / norm, r21 / norm) if norm > 0.0 else (1.0, 0.0)
        u0, u1, u2 = u.tolist()
        J = np.empty((3, 6))
        J[:, :3] = -R.T
        columns = [[a1 * u2 - a2 * u1, a2 * u0 - a0 * u2, a0 * u1 - a1 * u0]  # a_i x u, as np.cross has it
                   for a0, a1, a2 in ((1.0, 0.0, 0.0), (0.0, cos_phi, -sin_phi), (r20, r21, r22))]
        J[:, 3:] = np.array(columns).T
        out = J @ cov @ J.T
        return 0.5 * (out + out.T)

    @property
    def R_map_cam(self) -> FloatArray:
        """Camera axes in the map frame (3, 3)."""
        return self.pose.R.T

    @property
    def state(self) -> FloatArray:
        """The report's state ``[x, y, z, phi, theta, psi]`` of the camera in the map:
        its centre and the Z-Y-X Euler angles of ``R_map_cam`` (``Rz(psi) Ry(theta) Rx(phi)``)."""
        return np.concatenate([self.position, matrix_to_euler(self.R_map_cam)])

    def to_dict(self) -> dict:
        """JSON-ready summary."""
        return {"position": [float(v) for v in self.position], "state": [float(v) for v in self.state],
                "rms_px": float(self.pose.reprojection_rms), "used": self.used, "rejected": self.rejected,
                "unknown": self.unknown}


def estimate_camera_pose(
    detections: list[MarkerDetection], marker_map: MarkerMap, camera: Camera, *, pixel_sigma: float | None = None,
    max_residual: float = 3.0, max_iter: int = 30, n_starts: int = 2, start: Pose | None = None,
) -> MapPose | None:
    """Pose of the camera in ``marker_map`` from the markers detected in one image.

    Parameters
    ----------
    detections : list of MarkerDetection
        Markers found in the image, corners (4, 2) in pixels (ids not in the map are ignored
        and listed; a map marker detected more than once is not used, and listed as rejected:
        which detection is the marker is not known).
    marker_map : MarkerMap
        The markers' corners in the map frame, m.
    camera : Camera
        Intrinsics of the image; the corners are undistorted once.
    pixel_sigma : float, optional
        Corner noise (px) for the covariance; default estimated from the residuals.
    max_residual : float
        A marker whose RMS reprojection error exceeds this many px and three times the
        median marker's is dropped, and the fit repeated.
    max_iter : int
        Most Gauss-Newton iterations per fit.
    n_starts : int
        How many of the largest markers give starts: both closed-form planar poses of each
        (:func:`visloc.pose.planar_solutions`, the flip included), moved into the map frame;
        the one that reprojects all map corners best starts the joint fit.
    start : Pose, optional
        ``T_cam_map`` near the answer (the previous frame's, in a video): the joint fit
        starts there instead, and is kept if it drops no marker and every marker's RMS
        reprojection error stays within ``max_residual`` px; otherwise the fit is redone from
        the markers' own poses.

    Returns
    -------
    MapPose or None
        ``T_cam_map`` (``p_cam = R @ p_map + t``, m) with its covariance and the markers
        used, rejected and unknown; None when no marker of the map was seen or none gave a
        start in front of the camera.

    Raises
    ------
    TypeError
        ``marker_map`` is not a :class:`MarkerMap`, ``camera`` not a :class:`Camera` or
        ``start`` not a :class:`~visloc.types.Pose`.
    ValueError
        ``pixel_sigma`` (unless None) or ``max_residual`` not a finite number > 0;
        ``max_iter`` or ``n_starts`` not a whole number > 0; a detection of a map marker
        whose corners are not (4, 2) finite numbers (the message names the marker).
    """
    _check_options(marker_map, camera, start, pixel_sigma, max_residual, max_iter, n_starts)
    known, ids, repeated, unknown = _map_detections(detections, marker_map)
    if not known:
        return None
    try:
        px = np.array([d.corners for d in known], dtype=np.float64)  # (M, 4, 2)
    except (TypeError, ValueError):  # ragged, or not numbers
        px = None
    if px is None or px.shape[1:] != (4, 2) or not all_finite(px):
        raise ValueError(_bad_corners(known))
    all_ids, all_corners = marker_map.stacked
    obj = all_corners[np.searchsorted(all_ids, ids)]  # (M, 4, 3)
    xy = camera.normalize(px.reshape(-1, 2)).reshape(-1, 4, 2)  # (M, 4, 2)
    f = np.array([[camera.fx], [camera.fy]])
    fit = _started_fit(start, known, ids, obj, xy, f, marker_map, max_iter, max_residual, n_starts)
    if fit is None:
        return None
    best, keep, rejected, res, M = fit  # M: [J | r]^T [J | r] at best
    rejected = repeated + rejected
    n = 8 * int(keep.sum())  # residuals: two per corner
    rms = float(np.sqrt(M[6, 6] / n))
    cov = _covariance(M, n, pixel_sigma)
    R = euler_to_matrix(best[3:])
    pose = Pose(R, best[:3].copy(), rms, cov)
    return MapPose(pose, [i for i, k in zip(ids, keep, strict=True) if k], rejected, unknown,
                   {i: float(r) for i, r in zip(ids, res, strict=True)})


def _check_options(marker_map: MarkerMap, camera: Camera, start: Pose | None, pixel_sigma: float | None,
                   max_residual: float, max_iter: int, n_starts: int) -> None:
    """TypeError or ValueError naming the first of :func:`estimate_camera_pose`'s options
    that is wrong."""
    if not isinstance(marker_map, MarkerMap):
        raise TypeError(f"marker_map must be a MarkerMap, got {type(marker_map).__name__}")
    if not isinstance(camera, Camera):
        raise TypeError(f"camera must be a Camera, got {type(camera).__name__}")
    if start is not None and not isinstance(start, Pose):
        raise TypeError(f"start must be a Pose, got {type(start).__name__}")
    for name, v, integer in (("pixel_sigma", pixel_sigma, False), ("max_residual", max_residual, False),
                             ("max_iter", max_iter, True), ("n_starts", n_starts, True)):
        if (v is None and name == "pixel_sigma") or (type(v) in (int, float) and 0 < v < math.inf
                                                      and (not integer or int(v) == v)):
            continue  # (the usual values, at once)
        if (isinstance(v, bool) or not isinstance(v, (int, float, np.number)) or not np.isfinite(v) or v <= 0
                or (integer and int(v) != v)):
            kind = "a whole number" if integer else "a finite number"
            raise ValueError(f"estimate_camera_pose: {name} must be {kind} > 0, got {v!r}")


def _map_detections(detections: list[MarkerDetection],
                    marker_map: MarkerMap) -> tuple[list[MarkerDetection], list[int], list[int], list[int]]:
    """The detections of the map's markers seen once, their ids, the ids seen more than once
    (which copy is the marker is unknown: none is used) and the ids not in the map, sorted."""
    known, missing = [], set()
    for d in detections:  # one pass over the detections
        if d.id in marker_map:
            known.append(d)
        else:
            missing.add(int(d.id))
    ids = [int(d.id) for d in known]
    repeated: list[int] = []
    if len(set(ids)) < len(ids):
        repeated = sorted({i for i in ids if ids.count(i) > 1})
        known = [d for d, i in zip(known, ids, strict=True) if i not in repeated]
        ids = [int(d.id) for d in known]
    return known, ids, repeated, sorted(missing)


def _started_fit(start: Pose | None, known: list[MarkerDetection], ids: list[int], obj: FloatArray,
                 xy: FloatArray, f: FloatArray, marker_map: MarkerMap, max_iter: int, max_residual: float,
                 n_starts: int) -> tuple | None:
    """The joint fit (:func:`_joint_fit`'s tuple) from ``start`` when no marker disagrees
    with it, else from the markers' own poses (:func:`_best_start`); None: no start."""
    if start is not None:  # a pose near the answer: kept only if no marker disagrees with it
        fit = _joint_fit(np.concatenate([start.t, matrix_to_euler(start.R)]), obj, xy, f, ids,
                         max_iter, max_residual)
        _, kept, dropped, res, _ = fit
        if not (dropped or res[kept].max() > max_residual):
            return fit
    first = _best_start(known, ids, obj, xy, f, marker_map, n_starts)
    if first is None:
        return None
    return _joint_fit(first, obj, xy, f, ids, max_iter, max_residual)


def _bad_corners(known: list[MarkerDetection]) -> str:
    """The message naming the first detection whose corners are not (4, 2) finite numbers."""
    for d in known:
        try:
            c = np.asarray(d.corners, dtype=np.float64)
        except (TypeError, ValueError):
            return f"detections: marker {d.id}'s corners must be (4, 2) numbers, got {d.corners!r}"
        if c.shape != (4, 2):
            return f"detections: marker {d.id}'s corners must be (4, 2), got {c.shape}"
        if not np.isfinite(c).all():
            return f"detections: marker {d.id}'s corners must be finite, got {c.tolist()}"
    return "detections: each marker's corners must be (4, 2) finite numbers"


def _best_start(known: list[MarkerDetection], ids: list[int], obj: FloatArray, xy: FloatArray, f: FloatArray,
                marker_map: MarkerMap, n_starts: int) -> FloatArray | None:
    """The start of the joint fit (6,): of the own poses (and their flips) of the ``n_starts``
    largest markers in the image, moved into the map frame, the one that reprojects all map
    corners best; None when none is in front of the camera."""
    area = [abs(_area(d.corners)) for d in known]
    start_R, start_t = [], []
    for j in np.argsort(area)[::-1][:n_starts]:
        i = ids[j]
        L = float(np.linalg.norm(obj[j, 1] - obj[j, 0]))
        try:  # both closed-form planar poses of the marker: the joint fit refines the start
            Rs, ts = planar_solutions(xy[j], L)
        except np.linalg.LinAlgError:
            continue
        inv = marker_map.marker_pose(i).inverse()  # T_marker_map
        front = ts[:, 2] > 0  # in front of the camera
        start_R.append(Rs[front] @ inv.R)  # T_cam_marker composed with T_marker_map
        start_t.append(Rs[front] @ inv.t + ts[front])
    if not start_R or not (R_s := np.concatenate(start_R)).size:
        return None
    starts = np.concatenate([np.concatenate(start_t), matrix_to_euler(R_s)], axis=1)
    fit = (_marker_rms(starts, obj, xy, f) ** 2).mean(axis=-1)  # per start
    return np.array(starts[int(np.argmin(fit))])


def _joint_fit(params: FloatArray, obj: FloatArray, xy: FloatArray, f: FloatArray, ids: list[int],
               max_iter: int, max_residual: float
               ) -> tuple[FloatArray, NDArray[np.bool_], list[int], FloatArray, FloatArray]:
    """Gauss-Newton over all corners from ``params`` (6,), dropping the worst marker and
    fitting again while it disagrees with the rest: ``(params, kept, rejected ids, each
    marker's RMS px, M)``, ``M = [J | r]^T [J | r]`` (7, 7) of the kept corners at ``params``."""
    keep = np.ones(len(ids), bool)
    rejected: list[int] = []
    params = params[None]
    while True:
        X, x = (obj, xy) if not rejected else (obj[keep], xy[keep])  # (all kept: no copies)
        p, _, M = levenberg_marquardt(params, X.reshape(-1, 3).T, x.reshape(-1, 2).T, f, max_iter=max_iter)
        best = p[0]  # (one start)
        res = _marker_rms(best, obj, xy, f)
        r, k = res.tolist(), keep.tolist()  # a few values: no numpy
        limit = max(max_residual, 3.0 * median([v for v, kk in zip(r, k, strict=True) if kk]))
        scores = [v if kk else -1.0 for v, kk in zip(r, k, strict=True)]
        worst = scores.index(max(scores))  # the first largest, as np.argmax
        if len(ids) - len(rejected) <= 1 or scores[worst] <= limit:
            return best, keep, rejected, res, M[0]
        keep[worst] = False
        rejected.append(ids[worst])
        params = best[None]


def _area(corners: FloatArray) -> float:
    (x0, y0), (x1, y1), (x2, y2), (x3, y3) = corners.tolist()
    return 0.5 * ((x0 - x2) * (y1 - y3) - (x1 - x3) * (y0 - y2))  # half the diagonals' cross


def _marker_rms(params: FloatArray, obj: FloatArray, xy: FloatArray, f: FloatArray) -> FloatArray:
    """RMS reprojection error (px) of each marker's four corners under ``params`` (6,), or
    under each of several parameter vectors (S, 6): (M,) or (S, M)."""
    return reprojection_rms(params, obj.reshape(-1, 3).T, xy.reshape(-1, 2).T, f)


def _covariance(M: FloatArray, n_residuals: int, pixel_sigma: float | None) -> FloatArray | None:
    """``sigma^2 (J^T J)^-1`` from ``M = [J | r]^T [J | r]`` (7, 7)."""
    dof = max(n_residuals - 6, 1)
    var = float(pixel_sigma) ** 2 if pixel_sigma is not None else max(M[6, 6] / dof, MIN_PIXEL_SIGMA**2)
    try:
        inv = np.linalg.inv(M[:6, :6])
    except np.linalg.LinAlgError:
        return None
    cov = var * 0.5 * (inv + inv.T)
    return cov if all_finite(cov) and min(np.diag(cov).tolist()) > 0 else None


def markers_in_view(marker_map: MarkerMap, camera: Camera, pose: Pose, *, size: tuple[int, int] | None = None,
                    margin: float = 0.0) -> dict[int, FloatArray]:
    """The map's markers that a camera at ``pose`` sees whole, and where: what a
    :class:`visloc.markers.MarkerTracker` may be told to expect
    (``tracker.detect(image, expected=markers_in_view(map, camera, last_pose))``).

    Parameters
    ----------
    marker_map : MarkerMap
        The markers, corners in the map frame.
    camera : Camera
        Intrinsics (with distortion).
    pose : Pose
        ``T_cam_map`` (``p_cam = R @ p_map + t``), e.g. the previous frame's
        :attr:`MapPose.pose`.
    size : (int, int), optional
        ``(width, height)`` of the image, px (default ``camera.size``).
    margin : float
        Least distance of every corner from the image's edge pixels, px (>= 0).

    Returns
    -------
    dict of int to ndarray (4, 2)
        Marker id -> its corners in the image, px, in the map's corner order (the marker's
        own top-left corner first), for every marker whose four corners lie in front of the
        camera and ``margin`` inside the image.

    Raises
    ------
    TypeError
        ``marker_map``, ``camera`` or ``pose`` of the wrong type; ``size`` not a pair of
        numbers.
    ValueError
        No ``size`` given and none in ``camera``; a ``size`` of other than two finite whole
        numbers > 0; a pose whose ``R`` or ``t`` is not finite; ``margin`` not a finite
        number >= 0.
    """
    if not isinstance(marker_map, MarkerMap):
        raise TypeError(f"marker_map: expected a MarkerMap, got {type(marker_map).__name__}")
    if not isinstance(camera, Camera):
        raise TypeError(f"camera: expected a Camera, got {type(camera).__name__}")
    if not isinstance(pose, Pose):
        raise TypeError(f"pose: expected a Pose, got {type(pose).__name__}")
    if size is None:
        if camera.size is None:
            raise ValueError("size: give the image's (width, height); the camera has no size")
        w, h = camera.size  # checked by the Camera
    else:
        w, h = _image_size(size)
    if (type(margin) not in (float, int) and (isinstance(margin, bool) or not isinstance(margin, numbers.Real))
            or not 0 <= margin < math.inf):
        raise ValueError(f"margin must be a finite number >= 0, got {margin!r}")
    if not (all_finite(pose.R) and all_finite(pose.t)):
        raise ValueError(f"pose: R and t must be finite, got R={pose.R.tolist()}, t={pose.t.tolist()}")
    ids, obj = marker_map.stacked
    pc = obj.reshape(-1, 3) @ pose.R.T + pose.t  # (4M, 3)
    front = pc[:, 2] > 1e-6
    z = np.where(front, pc[:, 2], 1.0)
    px = pc[:, :2] / z[:, None] * np.array([camera.fx, camera.fy]) + np.array([camera.cx, camera.cy])
    if camera.has_distortion:  # only the markers whose pinhole image is near the frame: a distortion
        # polynomial far outside its calibrated field can fold points back into the image
        near = (front & (np.abs(px - 0.5 * np.array([w, h])) <= np.array([w, h])).all(axis=1)).reshape(-1, 4).all(axis=1)
        front = np.repeat(near, 4)
        if near.any():
            px[front] = camera.project(pc[front])
    x, y = px[:, 0], px[:, 1]
    inside = front & (x >= margin) & (y >= margin) & (x <= (w - 1.0) - margin) & (y <= (h - 1.0) - margin)
    whole = inside.reshape(-1, 4).all(axis=1)
    quads = px.reshape(-1, 4, 2)
    return {i: quads[k] for k, i in zip(np.flatnonzero(whole).tolist(), ids[whole].tolist(), strict=True)}


def _image_size(size: object) -> tuple[float, float]:
    """``size`` as given, once checked to be ``(width, height)``: two finite whole numbers > 0."""
    try:
        w, h = size  # type: ignore[misc]
    except (TypeError, ValueError) as exc:
        kind = TypeError if isinstance(exc, TypeError) or isinstance(size, (str, bytes)) else ValueError
        raise kind(f"size must be (width, height), two whole numbers, got {size!r}") from None
    if type(w) is int and type(h) is int and w > 0 and h > 0:  # the usual case, at once
        return w, h
    for v in (w, h):
        if isinstance(v, bool) or not isinstance(v, numbers.Real):
            raise TypeError(f"size must be (width, height), two whole numbers, got {size!r}")
        if not (0 < v < math.inf and v == math.floor(v)):
            raise ValueError(f"size must be (width, height), two finite whole numbers > 0, got {size!r}")
    return w, h
