"""Pinhole camera with OpenCV's lens-distortion model, or OpenCV's fisheye model.

:class:`Camera` holds the intrinsic matrix ``K``, OpenCV distortion coefficients, the model
(``"pinhole"``: ``cv2.projectPoints``' polynomial distortion; ``"fisheye"``: ``cv2.fisheye``'s
equidistant projection with four coefficients, for lenses of 120 degrees and more) and,
optionally, the image size the calibration belongs to. It reads and writes OpenCV
FileStorage YAML (the format of ``calib/*.yml`` and of OpenCV's calibration tools) and maps
points between pixels, undistorted pixels and normalized image coordinates.

Coordinates follow :mod:`visloc.types`: pixel centres at integer ``(x, y)``; the camera frame
is OpenCV's (x right, y down, z forward).
"""

from __future__ import annotations

import math
import re
from dataclasses import KW_ONLY, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np
from numpy.typing import ArrayLike

from visloc._storage import open_storage
from visloc.types import FloatArray

if TYPE_CHECKING:
    from visloc.types import Pose

#: Numbers of distortion coefficients OpenCV accepts.
DIST_SIZES = (4, 5, 8, 12, 14)
#: Camera models: OpenCV's pinhole with polynomial distortion, and its fisheye (``cv2.fisheye``:
#: ``r = f theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)``).
MODELS = ("pinhole", "fisheye")

# Undistortion is iterative; OpenCV's default (5 iterations) leaves ~0.01 px of error at the
# border of a strongly distorted 640x480 image (k1 = -0.3). This converges to ~1e-12 px.
_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12)


def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


def _as_points(points: ArrayLike, dim: int, name: str) -> FloatArray:
    p = np.asarray(points, dtype=np.float64)
    if p.ndim == 1 and p.shape[0] == dim:
        p = p[None, :]
    if p.ndim != 2 or p.shape[1] != dim:
        raise ValueError(f"{name} must have shape (N, {dim}), got {np.shape(points)}")
    return p


@dataclass(frozen=True, eq=False)
class Camera:
    """Intrinsics of a pinhole camera with OpenCV lens distortion.

    Parameters
    ----------
    K : array_like (3, 3)
        Camera matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` in pixels; ``fx, fy > 0``.
        Skew must be zero (OpenCV's distortion model ignores it).
    dist : array_like (4,), (5,), (8,), (12,) or (14,), optional
        OpenCV distortion coefficients ``(k1, k2, p1, p2[, k3[, k4, k5, k6[, s1..s4[, tx, ty]]]])``;
        ``None`` means no distortion (stored as ``zeros(5)``). With ``model="fisheye"``: the
        four coefficients ``(k1, k2, k3, k4)`` of ``cv2.fisheye`` (``None``: zeros, the
        ideal equidistant lens).
    size : (int, int), optional
        ``(width, height)`` in pixels of the images the calibration belongs to.
    model : {"pinhole", "fisheye"}
        The projection (:data:`MODELS`).

    Attributes
    ----------
    K : ndarray (3, 3) float64, read-only
    dist : ndarray (n,) float64, read-only
    size : tuple (width, height) or None
    model : str
    """

    K: FloatArray
    dist: FloatArray | None = None
    size: tuple[int, int] | None = None
    _: KW_ONLY
    model: str = "pinhole"
    _distorted: bool = field(init=False, default=False, repr=False)

    def __post_init__(self) -> None:
        K = np.array(self.K, dtype=np.float64)
        if K.shape != (3, 3):
            raise ValueError(f"K must have shape (3, 3), got {np.shape(self.K)}")
        if not np.all(np.isfinite(K)):
            raise ValueError(f"K must be finite, got {K.tolist()}")
        if not (K[0, 0] > 0 and K[1, 1] > 0):
            raise ValueError(f"K must have positive focal lengths, got fx={K[0, 0]}, fy={K[1, 1]}")
        if not np.array_equal(K[2], [0.0, 0.0, 1.0]):
            raise ValueError(f"K's last row must be [0, 0, 1], got {K[2].tolist()}")
        if K[0, 1] != 0.0 or K[1, 0] != 0.0:
            raise ValueError(
                f"K must have zero skew (K[0, 1] = K[1, 0] = 0), got {K[0, 1]}, {K[1, 0]}"
            )
        if self.model not in MODELS:
            raise ValueError(f"model must be one of {', '.join(MODELS)}, got {self.model!r}")
        fisheye = self.model == "fisheye"
        if self.dist is None:
            dist = np.zeros(4 if fisheye else 5)
        else:
            dist = np.array(self.dist, dtype=np.float64).reshape(-1)
            if dist.size not in DIST_SIZES:
                raise ValueError(
                    f"dist must have 4, 5, 8, 12 or 14 coefficients, got {dist.size} "
                    f"(shape {np.shape(self.dist)})"
                )
            if not np.all(np.isfinite(dist)):
                raise ValueError(f"dist must be finite, got {dist.tolist()}")
            if fisheye and dist.size != 4:
                raise ValueError(f"a fisheye camera has 4 distortion coefficients (k1..k4), got {dist.size}")
        size = self.size
        if size is not None:
            try:
                w, h = size
            except (TypeError, ValueError):
                raise ValueError(f"size must be (width, height), got {size!r}") from None
            if int(w) != w or int(h) != h or w <= 0 or h <= 0:
                raise ValueError(f"size must be two positive integers, got {size!r}")
            size = (int(w), int(h))
        object.__setattr__(self, "K", _readonly(K))
        object.__setattr__(self, "dist", _readonly(dist))
        object.__setattr__(self, "size", size)
        # the fisheye projection (r = f theta) differs from the pinhole one even with k = 0
        object.__setattr__(self, "_distorted", fisheye or bool(np.any(dist != 0.0)))

    # ------------------------------------------------------------------ properties
    @property
    def fx(self) -> float:
        """Focal length along x, pixels."""
        return float(self.K[0, 0])

    @property
    def fy(self) -> float:
        """Focal length along y, pixels."""
        return float(self.K[1, 1])

    @property
    def cx(self) -> float:
        """Principal point x, pixels."""
        return float(self.K[0, 2])

    @property
    def cy(self) -> float:
        """Principal point y, pixels."""
        return float(self.K[1, 2])

    @property
    def has_distortion(self) -> bool:
        """Whether any distortion coefficient is non-zero (always, for a fisheye camera)."""
        return self._distorted

    def __repr__(self) -> str:
        size = "None" if self.size is None else f"({self.size[0]}, {self.size[1]})"
        dist = ", ".join(f"{d:.6g}" for d in self.dist) if self.has_distortion else "none"
        model = ", model='fisheye'" if self.model == "fisheye" else ""
        return (
            f"Camera(fx={self.fx:.6g}, fy={self.fy:.6g}, cx={self.cx:.6g}, cy={self.cy:.6g}, "
            f"dist=[{dist}], size={size}{model})"
        )

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_fov(
        cls,
        width: int,
        height: int,
        hfov_deg: float | None = None,
        *,
        dfov_deg: float | None = None,
        dist: ArrayLike | None = None,
    ) -> Camera:
        """An ideal camera (square pixels, centred principal point) from a field of view.

        Parameters
        ----------
        width, height : int
            Image size, pixels.
        hfov_deg : float, optional
            Horizontal field of view, degrees, in (0, 180).
        dfov_deg : float, optional, keyword-only
            Diagonal field of view instead (as camera data sheets often give it).
        dist : array_like, optional
            Distortion coefficients to attach.

        Notes
        -----
        ``f = (extent / 2) / tan(fov / 2)`` with ``extent`` the image width or diagonal in
        pixels; the principal point is the image centre ``((width - 1) / 2, (height - 1) / 2)``
        under the pixel-centre convention.
        """
        if (hfov_deg is None) == (dfov_deg is None):
            raise ValueError("give exactly one of hfov_deg and dfov_deg")
        fov = hfov_deg if hfov_deg is not None else dfov_deg
        name = "hfov_deg" if hfov_deg is not None else "dfov_deg"
        if not (math.isfinite(fov) and 0.0 < fov < 180.0):
            raise ValueError(f"{name} must be in (0, 180) degrees, got {fov}")
        if int(width) != width or int(height) != height or width <= 0 or height <= 0:
            raise ValueError(f"width and height must be positive integers, got {width}, {height}")
        extent = width if hfov_deg is not None else math.hypot(width, height)
        f = 0.5 * extent / math.tan(math.radians(fov) / 2.0)
        K = np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0, 0, 1.0]])
        return cls(K, dist, (int(width), int(height)))

    @classmethod
    def from_file(cls, path: str | Path) -> Camera:
        """Read an OpenCV FileStorage file (YAML/XML/JSON).

        Reads ``camera_matrix`` (required), ``distortion_coefficients`` (optional, zeros when
        absent), ``image_width`` / ``image_height`` (optional, ``size=None`` when absent) and
        ``distortion_model`` (optional: ``fisheye`` gives a fisheye camera, any other value or
        none a pinhole one, as ``visloc calibrate --model`` writes it).

        Parameters
        ----------
        path : str or Path
            The camera file (e.g. ``calib/*.yml``).

        Returns
        -------
        Camera
            ``K`` (px), distortion coefficients, ``size`` ``(width, height)`` px or None, and
            the model.

        Raises
        ------
        ValueError
            When the file is missing, empty or not OpenCV FileStorage, has no
            ``camera_matrix``, a matrix node that is not an ``opencv-matrix``, a non-integer
            ``image_width`` / ``image_height`` or only one of them, or values
            :class:`Camera` rejects; the message names the path and the problem.
        """
        path = Path(path)
        fs = open_storage(path, "camera file")
        try:
            K = cls._read_matrix(fs, "camera_matrix", path, required=True)
            dist = cls._read_matrix(fs, "distortion_coefficients", path, required=False)
            w = cls._read_int(fs, "image_width", path)
            h = cls._read_int(fs, "image_height", path)
            node = fs.getNode("distortion_model")
            model = "fisheye" if node.isString() and node.string().strip().lower() == "fisheye" else "pinhole"
        finally:
            fs.release()
        if (w is None) != (h is None):
            raise ValueError(
                f"camera file {str(path)!r} has only one of image_width and image_height"
            )
        try:
            return cls(
                K, None if dist is None or dist.size == 0 else dist, None if w is None else (w, h), model=model
            )
        except ValueError as exc:
            raise ValueError(f"camera file {str(path)!r}: {exc}") from None

    @staticmethod
    def _read_matrix(
        fs: cv2.FileStorage, key: str, path: Path, *, required: bool
    ) -> FloatArray | None:
        node = fs.getNode(key)
        if node.empty() or node.isNone():
            if required:
                raise ValueError(f"camera file {str(path)!r} has no {key!r}")
            return None
        m = None
        if node.isMap():
            try:
                m = node.mat()
            except cv2.error:
                m = None
        if m is None:
            raise ValueError(f"camera file {str(path)!r}: {key!r} is not an opencv-matrix")
        return np.asarray(m, dtype=np.float64)

    @staticmethod
    def _read_int(fs: cv2.FileStorage, key: str, path: Path) -> int | None:
        node = fs.getNode(key)
        if node.empty() or node.isNone():
            return None
        if not node.isInt():
            raise ValueError(f"camera file {str(path)!r}: {key!r} is not an integer")
        return int(node.real())

    def to_file(self, path: str | Path, *, extra: dict | None = None) -> None:
        """Write OpenCV FileStorage YAML that :meth:`from_file` reads back.

        Writes ``image_width`` / ``image_height`` when ``size`` is known, ``camera_matrix``,
        ``distortion_coefficients`` (a column), then the nodes of ``extra`` and, for a fisheye
        camera, ``distortion_model: fisheye``. The file is YAML whatever its extension.

        Parameters
        ----------
        path : str or Path
            The file to write; an existing file is overwritten, the folder must exist.
        extra : dict, optional, keyword-only
            More nodes, name -> number, string or array of numbers (a list or ndarray, written
            as a float64 matrix; e.g. a calibration's figures), written as
            ``cv2.FileStorage.write`` writes them.

        Raises
        ------
        TypeError
            If an ``extra`` value is none of those (checked before the file is opened: no
            half-written file).
        ValueError
            If an ``extra`` name is not a FileStorage node name (a letter or ``_``, then
            letters, digits, ``_`` or ``-``), or the file cannot be opened for writing.
        """
        path = Path(path)
        nodes = {key: _storage_value(key, value) for key, value in dict(extra or {}).items()}
        if self.model == "fisheye":
            nodes["distortion_model"] = "fisheye"
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_FORMAT_YAML)
        if not fs.isOpened():
            raise ValueError(f"camera file {str(path)!r} could not be opened for writing")
        try:
            if self.size is not None:
                fs.write("image_width", int(self.size[0]))
                fs.write("image_height", int(self.size[1]))
            fs.write("camera_matrix", np.ascontiguousarray(self.K))
            fs.write("distortion_coefficients", np.ascontiguousarray(self.dist.reshape(-1, 1)))
            for key, value in nodes.items():
                fs.write(key, value)
        finally:
            fs.release()

    def scaled(self, width: int, height: int) -> Camera:
        """The same camera for images resized to ``(width, height)``.

        Pixel centres sit at integer coordinates, so a resize by ``s`` maps ``x`` to
        ``(x + 0.5) * s - 0.5`` (as ``cv2.resize`` does); focal lengths scale by ``s``.
        Distortion coefficients act on normalized coordinates and are unchanged.

        Parameters
        ----------
        width, height : int
            The new image size, px (> 0); x and y scale independently by ``width / size[0]``
            and ``height / size[1]``.

        Returns
        -------
        Camera
            The scaled ``K``, the same distortion coefficients and model, ``size=(width,
            height)``.

        Raises
        ------
        ValueError
            If this camera has ``size=None``, or ``width`` or ``height`` is not a positive
            integer.
        """
        if self.size is None:
            raise ValueError("scaled() needs the calibration's size; this camera has size=None")
        if int(width) != width or int(height) != height or width <= 0 or height <= 0:
            raise ValueError(f"width and height must be positive integers, got {width}, {height}")
        sx = width / self.size[0]
        sy = height / self.size[1]
        K = self.K.copy()
        K[0, 0] *= sx
        K[1, 1] *= sy
        K[0, 2] = (K[0, 2] + 0.5) * sx - 0.5
        K[1, 2] = (K[1, 2] + 0.5) * sy - 0.5
        return Camera(K, self.dist.copy(), (int(width), int(height)), model=self.model)

    # ------------------------------------------------------------------ point mappings
    def normalize(self, points: ArrayLike) -> FloatArray:
        """Normalized image coordinates ``(x/z, y/z)`` of (N, 2) pixel points (distortion removed).

        Parameters
        ----------
        points : array_like (N, 2) or (2,)
            Pixel coordinates ``(x, y)``, px, pixel centres at integers, in the distorted
            image.

        Returns
        -------
        ndarray (N, 2) float64
            ``(x/z, y/z)`` of the rays through the points, camera frame (dimensionless); a
            single point gives (1, 2).

        Raises
        ------
        ValueError
            If ``points`` is not (N, 2) or (2,).
        """
        p = _as_points(points, 2, "points")
        if not self.has_distortion:
            return (p - self.K[:2, 2]) / self.K[[0, 1], [0, 1]]
        if not len(p):  # OpenCV returns None for no points
            return np.zeros((0, 2))
        src = p.reshape(-1, 1, 2)
        if self.model == "fisheye":
            out = cv2.fisheye.undistortPoints(src, self.K, self.dist, criteria=_UNDISTORT_CRITERIA)
            return out.reshape(-1, 2).astype(np.float64, copy=False)
        if hasattr(cv2, "undistortPointsIter"):  # OpenCV 4.x: the iteration criteria's own function
            out = cv2.undistortPointsIter(src, self.K, self.dist, None, None, _UNDISTORT_CRITERIA)
        else:  # OpenCV 5: undistortPoints takes them
            out = cv2.undistortPoints(src, self.K, self.dist, criteria=_UNDISTORT_CRITERIA)
        return out.reshape(-1, 2).astype(np.float64, copy=False)

    def undistort_points(self, points: ArrayLike) -> FloatArray:
        """Pixel coordinates, in the ideal pinhole camera with the same ``K``, of (N, 2) points.

        The identity when there is no distortion.

        Parameters
        ----------
        points : array_like (N, 2) or (2,)
            As for :meth:`normalize`: pixels of the distorted image.

        Returns
        -------
        ndarray (N, 2) float64
            The undistorted pixel coordinates, px (a copy of ``points`` without distortion); a
            single point gives (1, 2).

        Raises
        ------
        ValueError
            If ``points`` has neither shape.
        """
        p = _as_points(points, 2, "points")
        if not self.has_distortion:
            return p.copy()
        return self.normalize(p) * self.K[[0, 1], [0, 1]] + self.K[:2, 2]

    def project(self, points_cam: ArrayLike) -> FloatArray:
        """Pixels (with distortion) of (N, 3) points given in the camera frame.

        Points must lie in front of the camera (``z > 0``); others give meaningless pixels.

        Parameters
        ----------
        points_cam : array_like (N, 3) or (3,)
            Points ``(x, y, z)`` in the camera frame (x right, y down, z forward), m (any
            unit: only the ratios count).

        Returns
        -------
        ndarray (N, 2) float64
            Their pixel coordinates, px, pixel centres at integers, lens distortion applied;
            a single point gives (1, 2).

        Raises
        ------
        ValueError
            If ``points_cam`` is not (N, 3) or (3,).
        """
        p = _as_points(points_cam, 3, "points_cam")
        if not self.has_distortion:
            xy = p[:, :2] / p[:, 2:3]
            return xy * self.K[[0, 1], [0, 1]] + self.K[:2, 2]
        if not len(p):  # OpenCV returns None for no points
            return np.zeros((0, 2))
        zero = np.zeros(3)
        if self.model == "fisheye":
            out, _ = cv2.fisheye.projectPoints(p.reshape(-1, 1, 3), zero, zero, self.K, self.dist)
            return out.reshape(-1, 2).astype(np.float64, copy=False)
        out, _ = cv2.projectPoints(p.reshape(-1, 1, 3), zero, zero, self.K, self.dist)
        return out.reshape(-1, 2).astype(np.float64, copy=False)

    def project_object(self, points_obj: ArrayLike, pose: Pose) -> FloatArray:
        """Pixels of (N, 3) object points seen with ``pose`` (object frame into camera frame).

        Parameters
        ----------
        points_obj : array_like (N, 3) or (3,)
            Points in the object frame (marker, map, ...), m.
        pose : Pose
            ``T_cam_obj``: ``p_cam = R @ p_obj + t`` (:meth:`visloc.types.Pose.apply`).

        Returns
        -------
        ndarray (N, 2) float64
            Pixel coordinates, px, pixel centres at integers, lens distortion applied, as
            :meth:`project`; a single point gives (1, 2).

        Raises
        ------
        ValueError
            If ``points_obj`` is not (N, 3) or (3,).
        """
        p = _as_points(points_obj, 3, "points_obj")
        return self.project(pose.apply(p))


def _storage_value(key: object, value: object) -> int | float | str | np.ndarray:
    """``value`` as :meth:`Camera.to_file` writes it under ``key`` (an int, float, str or a
    float64 array), or ``ValueError`` / ``TypeError`` naming the node."""
    if not isinstance(key, str) or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_-]*", key):
        raise ValueError(f"extra: {key!r} is not a FileStorage node name")
    if isinstance(value, (bool, np.bool_)):
        return int(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value)
    if isinstance(value, str):
        return value
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"extra[{key!r}]: expected a number, a string or an array of numbers, "
                        f"got {type(value).__name__}") from None
    if arr.ndim > 2 or arr.size == 0:
        raise TypeError(f"extra[{key!r}]: expected an array of up to 2 dimensions with values, got shape {arr.shape}")
    return np.ascontiguousarray(arr.reshape(-1, 1) if arr.ndim < 2 else arr)
