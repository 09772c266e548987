"""Shared data types and the conventions every visloc module keeps.

Conventions
-----------
Images
    numpy ``uint8`` arrays, ``H x W`` grey. ``H x W x 3`` BGR is accepted at public entry
    points and converted once (:func:`visloc.images.as_gray`).
Pixel coordinates
    ``(x, y)`` floats; the *centre* of pixel ``(col, row)`` sits at the integer coordinate
    ``(col, row)`` (OpenCV's convention). A pixel covers ``[col - 0.5, col + 0.5]``.
Marker corners
    ``(4, 2)`` per marker, clockwise in the image from the marker's own top-left:
    top-left, top-right, bottom-right, bottom-left (OpenCV ArUco order).
Marker frame
    Origin at the marker centre, x right, y up, z out of the printed face. The corners of a
    marker of side ``L`` are ``(-L/2, L/2, 0), (L/2, L/2, 0), (L/2, -L/2, 0), (-L/2, -L/2, 0)``
    (OpenCV's ``SOLVEPNP_IPPE_SQUARE`` object points, in corner order).
Camera frame
    OpenCV's: x right, y down, z forward along the optical axis (rerun's RDF).
Pose
    ``Pose(R, t)`` maps points of the object frame (marker, map, body) into the camera
    frame: ``p_cam = R @ p_obj + t``. Compositions are named ``T_a_b`` (maps b into a).
Euler angles
    Z-Y-X (report, §2): ``R = Rz(psi) @ Ry(theta) @ Rx(phi)``; the report's parameter
    vector is ``[x, y, z, phi, theta, psi]``.
Units
    SI everywhere (m, s, rad); degrees only in output meant for people.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Frame:
    """One image from a frame source.

    Attributes
    ----------
    index : int
        Position of the frame in its source, from 0.
    time : float
        Seconds since the start of the source (video timestamp, or index / fps, or the
        wall-clock time since the first frame for cameras).
    image : ndarray (H, W) or (H, W, 3) uint8, or None
        The pixels; ``None`` when the frame could not be read (see ``error``).
    name : str
        Human-readable origin: a file path, or ``"video.mp4#12"``, or ``"camera0#12"``.
    error : str or None
        Why the frame could not be read, or ``None``.
    """

    index: int
    time: float
    image: NDArray[np.uint8] | None
    name: str
    error: str | None = None


@dataclass(frozen=True, eq=False)
class MarkerDetection:
    """A decoded square fiducial marker.

    Attributes
    ----------
    id : int
        Index of the marker in its dictionary.
    corners : ndarray (4, 2) float64
        Sub-pixel image corners, clockwise from the marker's own top-left (OpenCV order),
        pixel centres at integer coordinates.
    hamming : int
        Number of bits the dictionary match corrected (0 = exact).
    margin : float
        Decoding margin in [0, 1]: the smallest distance of any cell's mean intensity from
        the marker's threshold, divided by half the marker's black/white contrast. Near 0
        means some cell was ambiguous; near 1 means every cell was clearly black or white.
    rotation : int
        How many quarter turns (clockwise in the image) the marker's top-left corner was
        found away from the first corner of the contour; informational.
    contrast : float
        White level minus black level of the marker in grey levels.
    refined : bool
        Whether the corners come from the grey-level edge refinement (stage 8); False when
        it failed (occluded or cluttered sides) and the contour line fits were kept.
    confidence : float
        Bit certainty in [0, 1], OpenCV's definition: 1 minus the share of the marker's read
        area (every cell, border included, less a margin) whose colour contradicts the
        decoded code. 1 for a clean read; corrected bits and stained cells lower it. NaN
        when the detector did not read it (``DetectorParams.confidence=False``).
    inverted : bool
        Whether the marker is white on black (found with ``inverted=True`` or ``"both"``).
    """

    id: int
    corners: FloatArray
    hamming: int = 0
    margin: float = 1.0
    rotation: int = 0
    contrast: float = 0.0
    refined: bool = True
    confidence: float = 1.0
    inverted: bool = False

    @property
    def center(self) -> FloatArray:
        """Intersection of the marker's diagonals, (2,) float."""
        p = self.corners
        d1 = p[2] - p[0]
        d2 = p[3] - p[1]
        a = np.array([[d1[0], -d2[0]], [d1[1], -d2[1]]])
        try:
            s = np.linalg.solve(a, p[1] - p[0])[0]
        except np.linalg.LinAlgError:
            return p.mean(axis=0)
        return p[0] + s * d1

    def to_dict(self) -> dict:
        """JSON-ready dict: ``id``, ``corners`` (list of [x, y]), ``hamming``, ``margin``,
        ``confidence`` (null when not read), ``refined`` and, for white-on-black markers,
        ``inverted``."""
        out = {
            "id": int(self.id),
            "corners": [[round(float(x), 4), round(float(y), 4)] for x, y in self.corners],
            "hamming": int(self.hamming),
            "margin": round(float(self.margin), 4),
            "confidence": round(float(self.confidence), 4) if math.isfinite(self.confidence) else None,
            "refined": bool(self.refined),
        }
        if self.inverted:
            out["inverted"] = True
        return out


@dataclass(frozen=True, eq=False)
class Pose:
    """A rigid transform from an object frame into the camera frame: ``p_cam = R @ p_obj + t``.

    Attributes
    ----------
    R : ndarray (3, 3)
        Rotation matrix (object axes expressed in camera axes).
    t : ndarray (3,)
        Object origin in camera coordinates, metres.
    reprojection_rms : float
        RMS image distance (px) between the observed corners and the projected model.
    covariance : ndarray (6, 6) or None
        Covariance of ``params`` (``[tx, ty, tz, phi, theta, psi]``; m and rad) from the
        Gauss-Newton Jacobian and the pixel noise.
    alternative : Pose or None
        The other planar solution (the "flipped" pose) when one exists.
    alternative_rms : float or None
        Reprojection RMS of ``alternative``; when it is close to ``reprojection_rms`` the
        pose may flip between frames.
    """

    R: FloatArray
    t: FloatArray
    reprojection_rms: float = float("nan")
    covariance: FloatArray | None = None
    alternative: Pose | None = field(default=None, repr=False)
    alternative_rms: float | None = None

    @property
    def rvec(self) -> FloatArray:
        """Rodrigues rotation vector (3,) of ``R`` (OpenCV's ``rvec``)."""
        from scipy.spatial.transform import Rotation

        return Rotation.from_matrix(self.R).as_rotvec()

    @property
    def euler_zyx(self) -> FloatArray:
        """``[phi, theta, psi]`` with ``R = Rz(psi) Ry(theta) Rx(phi)`` (report §2)."""
        from scipy.spatial.transform import Rotation

        psi, theta, phi = Rotation.from_matrix(self.R).as_euler("ZYX")
        return np.array([phi, theta, psi])

    @property
    def params(self) -> FloatArray:
        """The report's parameter vector ``[x, y, z, phi, theta, psi]`` of this transform."""
        return np.concatenate([self.t, self.euler_zyx])

    @property
    def matrix(self) -> FloatArray:
        """4x4 homogeneous matrix ``[[R, t], [0, 1]]``."""
        m = np.eye(4)
        m[:3, :3] = self.R
        m[:3, 3] = self.t
        return m

    def inverse(self) -> Pose:
        """The transform the other way round (camera into object frame)."""
        return Pose(self.R.T, -self.R.T @ self.t, self.reprojection_rms)

    def compose(self, other: Pose) -> Pose:
        """``self ∘ other``: if self is T_a_b and other is T_b_c, returns T_a_c.

        Parameters
        ----------
        other : Pose
            ``T_b_c``, mapping c-frame points into frame b (``self`` maps b into a).

        Returns
        -------
        Pose
            ``T_a_c``: ``R = self.R @ other.R``, ``t = self.R @ other.t + self.t`` (m); the
            fit figures (``reprojection_rms``, ``covariance``, ``alternative``) are not
            carried over.
        """
        return Pose(self.R @ other.R, self.R @ other.t + self.t)

    def apply(self, points: FloatArray) -> FloatArray:
        """Map (N, 3) object points into the camera frame.

        Parameters
        ----------
        points : array_like (N, 3) or (3,)
            Points in the object frame (marker, map, body), m.

        Returns
        -------
        ndarray (N, 3) or (3,) float64
            ``R @ p + t`` for each point, m, camera frame (the shape of ``points``).
        """
        return np.asarray(points, float) @ self.R.T + self.t

    def to_dict(self) -> dict:
        """JSON-ready dict: ``rvec``, ``tvec``, ``R``, ``rms``, Euler angles and flip info."""
        d = {
            "rvec": [float(v) for v in self.rvec],
            "tvec": [float(v) for v in self.t],
            "R": [[float(v) for v in row] for row in self.R],
            "euler_zyx_rad": [float(v) for v in self.euler_zyx],
            "reprojection_rms_px": float(self.reprojection_rms),
        }
        if self.alternative_rms is not None:
            d["alternative_rms_px"] = float(self.alternative_rms)
        if self.covariance is not None:
            d["std"] = [float(v) for v in np.sqrt(np.clip(np.diag(self.covariance), 0, None))]
        return d


@dataclass(frozen=True, eq=False)
class FlowField:
    """Sparse optical flow of image blocks between two frames.

    Attributes
    ----------
    centers : ndarray (N, 2)
        Block centres (x, y) in the first frame, pixel-centre convention.
    vectors : ndarray (N, 2)
        Displacement (dx, dy) of the image content of each block from the first frame to the
        second, px.
    confidence : ndarray (N,)
        In [0, 1]: 0 for blocks without texture or with an ambiguous match.
    block : int
        Block side, px.
    image_size : (int, int)
        ``(width, height)`` of the frames.
    """

    centers: FloatArray
    vectors: FloatArray
    confidence: FloatArray
    block: int
    image_size: tuple[int, int]


@dataclass(frozen=True, eq=False)
class GlobalMotion:
    """The image content's motion between two frames as a rotation plus a translation.

    Attributes
    ----------
    translation : ndarray (2,)
        Displacement (px) of the content at the image centre ``((W-1)/2, (H-1)/2)``.
    rotation : float
        Rotation (rad) of the content, positive turning image +x toward image +y.
    scale : float
        Scale change (1 = none; > 1 when the content grows, i.e. the camera descends).
    center_of_rotation : ndarray (2,) or None
        Centre of instantaneous rotation (px), ``None`` when the motion is a pure
        translation (the centre is at infinity).
    residual_rms : float
        RMS of the flow vectors' residuals to the model, px, over the inliers.
    inliers : int
        Number of blocks used.
    method : str
        ``"similarity"`` or ``"cir"`` (report Appendix H).
    """

    translation: FloatArray
    rotation: float
    scale: float
    center_of_rotation: FloatArray | None
    residual_rms: float
    inliers: int
    method: str

    def displacement_at(self, point: FloatArray, image_center: FloatArray) -> FloatArray:
        """Content displacement (2,) at ``point`` (px) under this motion, ``image_center``
        being the point its translation refers to.

        The content at ``p`` moves by ``(scale * R(rotation) - I) @ (p - image_center) +
        translation``; ``center_of_rotation`` is not used.

        Parameters
        ----------
        point : array_like (2,)
            Image point ``(x, y)``, px, pixel centres at integers.
        image_center : array_like (2,)
            The point ``translation`` refers to, px: ``((W-1)/2, (H-1)/2)`` of the frames.

        Returns
        -------
        ndarray (2,) float64
            Displacement ``(dx, dy)`` of the content at ``point`` from the first frame to the
            second, px.
        """
        x, y = float(point[0]) - float(image_center[0]), float(point[1]) - float(image_center[1])
        c, s = math.cos(self.rotation) * self.scale, math.sin(self.rotation) * self.scale
        tx, ty = float(self.translation[0]), float(self.translation[1])
        return np.array([c * x - s * y - x + tx, s * x + c * y - y + ty])


@dataclass(frozen=True, eq=False)
class GroundVelocity:
    """Camera velocity over flat ground from two frames.

    Attributes
    ----------
    v : ndarray (2,)
        Camera velocity relative to the ground, m/s, in the first frame's camera axes: x right
        and y down as in the image (a camera moving toward +x makes the content move toward
        -x).
    yaw_rate : float
        Camera rotation rate about its +z axis (the optical axis, toward the ground),
        rad/s, right-handed: positive turns camera +x toward camera +y.
    quality : float
        In [0, 1]; 0 when nothing could be measured (then ``v`` and ``yaw_rate`` are 0).
    reason : str
        Why the quality is low ("" when it is fine).
    motion : GlobalMotion or None
        The image motion it came from.
    """

    v: FloatArray
    yaw_rate: float
    quality: float
    reason: str = ""
    motion: GlobalMotion | None = None

    def to_dict(self) -> dict:
        """JSON-ready dict: ``vx``, ``vy``, ``yaw_rate``, ``quality``, ``reason``."""
        return {"vx": float(self.v[0]), "vy": float(self.v[1]), "yaw_rate": float(self.yaw_rate),
                "quality": float(self.quality), "reason": self.reason}
