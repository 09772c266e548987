"""Simulated sensors of the AR.Drone 2.0: IMU, ultrasound and the bottom camera over a marker map.

Frames. The model's inertial frame A is NED with its origin on the floor (the floor is
``z = 0``, the drone flies at ``z < 0``). The marker map lies on the floor with z up and its
centre below A's origin: ``p_map = centre + D p_A`` with ``D = diag(1, -1, -1)`` (map x =
north, map y = west, map z = up). The bottom camera sits at the centre of gravity looking
down: camera z = body z (down), camera x = body y (right), camera y = -body x (the top of
the image points forward), ``p_cam = C p_body`` with :data:`BODY_TO_CAMERA`.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from visloc._checks import check_int
from visloc.control._checks import check_real
from visloc.estimation.height import ultrasound_reading
from visloc.pose.maps import MarkerMap
from visloc.synth.flight import default_bottom_camera
from visloc.synth.floor import FloorTexture
from visloc.types import FloatArray, Pose

__all__ = ["BODY_TO_CAMERA", "MAP_FROM_NED", "BottomCamera", "Imu", "Ultrasound"]

BODY_TO_CAMERA: FloatArray = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
"""``C`` with ``p_cam = C p_body`` for the downward camera (module docstring)."""

MAP_FROM_NED: FloatArray = np.diag([1.0, -1.0, -1.0])
"""``D`` with ``p_map = centre + D p_A`` (module docstring); ``D`` is its own inverse."""


class Imu:
    """Gyroscope and accelerometer in body axes with white noise and a constant gyro bias.

    Parameters
    ----------
    gyro_noise : float
        Standard deviation of each gyro sample, rad/s.
    accel_noise : float
        Standard deviation of each accelerometer sample, m/s^2.
    gyro_bias : array_like (3,)
        Constant gyro bias, rad/s.
    rng : numpy.random.Generator
        Noise source.
    """

    def __init__(self, *, gyro_noise: float = 0.005, accel_noise: float = 0.05,
                 gyro_bias: tuple[float, float, float] = (0.0, 0.0, 0.0),
                 rng: np.random.Generator | None = None) -> None:
        self.gyro_noise = check_real(gyro_noise, "gyro_noise", nonneg=True)
        self.accel_noise = check_real(accel_noise, "accel_noise", nonneg=True)
        self.gyro_bias = np.asarray(gyro_bias, dtype=float)
        if self.gyro_bias.shape != (3,) or not np.all(np.isfinite(self.gyro_bias)):
            raise ValueError(f"gyro_bias: expected 3 finite rad/s, got {gyro_bias!r}")
        self.rng = rng if rng is not None else np.random.default_rng()

    def sample(self, state: FloatArray, R: FloatArray, acceleration: FloatArray, g: float
               ) -> tuple[FloatArray, FloatArray]:
        """One sample of a body in ``state``.

        ``gyro = omega + bias + noise`` and the specific force ``accel = R^T (nu' - g e3) +
        noise`` (level at rest: ``(0, 0, -g)``, the convention of :mod:`visloc.estimation`).

        Parameters
        ----------
        state : ndarray (12,)
            The body's state (:data:`visloc.model.STATE_NAMES`); its body rates (rad/s) are read.
        R : ndarray (3, 3)
            Attitude, body to A (NED).
        acceleration : ndarray (3,)
            Inertial acceleration ``nu'``, m/s^2, in A (:meth:`visloc.sim.Vehicle.acceleration`).
        g : float
            Gravity, m/s^2.

        Returns
        -------
        gyro : ndarray (3,)
            Body rates, rad/s, body axes.
        accel : ndarray (3,)
            Specific force, m/s^2, body axes.
        """
        gyro = state[9:12] + self.gyro_bias + self.rng.normal(0.0, self.gyro_noise, 3)
        f = R.T @ (acceleration - np.array([0.0, 0.0, g]))
        return gyro, f + self.rng.normal(0.0, self.accel_noise, 3)


class Ultrasound:
    """The height sensor of report §3.2.1 (eq. 3.12) with white noise on the reading."""

    def __init__(self, *, noise: float = 0.5, rng: np.random.Generator | None = None) -> None:
        self.noise = check_real(noise, "noise", nonneg=True)
        self.rng = rng if rng is not None else np.random.default_rng()

    def sample(self, state: FloatArray, R: FloatArray) -> float:
        """The reading for the distance along body z to the floor ``z = 0`` (report eq. 3.12).

        Parameters
        ----------
        state : ndarray (12,)
            The body's state; its height ``-z`` (m, A is NED) is read.
        R : ndarray (3, 3)
            Attitude, body to A: the beam's tilt lengthens the distance by ``1 / R[2, 2]``.

        Returns
        -------
        float
            The reading, sensor units (:func:`visloc.estimation.height.ultrasound_reading`),
            with the noise added; 0 where the sensor reads nothing (its blind zone).
        """
        cos_tilt = max(float(R[2, 2]), 1e-3)
        reading = float(ultrasound_reading(max(-state[2] / cos_tilt, 0.0)))
        return reading + float(self.rng.normal(0.0, self.noise)) if reading > 0 else 0.0


class BottomCamera:
    """The downward camera over a marker map on the floor (rendered with :class:`FloorTexture`).

    Parameters
    ----------
    marker_map : MarkerMap
        Markers on the floor (map z = 0, z up).
    dictionary : str
        Their dictionary.
    size : (int, int)
        Image ``(width, height)``; ``K`` is the AR.Drone 2.0 bottom camera scaled to it.
    noise_sigma : float
        Sensor noise, grey levels: white Gaussian noise, rounded to whole levels, added to each
        frame and clipped to 0-255. Each frame takes a window at a random offset of one noise
        field of twice the image's width and height, drawn from ``rng`` at the first frame
        (at 320 x 240, about 10 us a frame against over 1 ms to draw the noise anew, measured
        warm on 2026-12-03): the noise is white within a frame, and two frames share noise only shifted by
        the difference of their offsets, which the markers under it do not follow.
    rng : numpy.random.Generator
        Noise source (the field and the offsets).
    supersample : int
        Texture samples per pixel axis (1-8; :meth:`visloc.synth.FloorTexture.render`). 1, the
        default: one bilinear sample per pixel of the texture level whose texels are about the
        pixel's size (the level is already an area average of the finer texture), a quarter of
        the warp of 2. Noise-free, the detector's corners then lie 0.066 px RMS from the true
        projections, against 0.045 px with 2 (30 views of a 4 x 4 grid).

    Attributes
    ----------
    K : ndarray (3, 3)
    centre : ndarray (3,)
        Map point below the inertial origin: the centre of the map's markers.
    """

    def __init__(self, marker_map: MarkerMap, dictionary: str, *, size: tuple[int, int] = (320, 240),
                 noise_sigma: float = 2.0, rng: np.random.Generator | None = None,
                 supersample: int = 1) -> None:
        self.floor = FloorTexture.from_map(marker_map, dictionary)
        self.marker_map = marker_map
        self.dictionary = dictionary
        self.size = size
        self.K = default_bottom_camera(size)
        self.noise_sigma = check_real(noise_sigma, "noise_sigma", nonneg=True)
        self.supersample = check_int(supersample, "supersample", low=1, high=8)
        self.rng = rng if rng is not None else np.random.default_rng()
        # the noise field, drawn at the first frame: its light and its dark part (uint8 each)
        self._grain: tuple[NDArray[np.uint8], NDArray[np.uint8]] | None = None
        pts = np.concatenate([marker_map.corners_of(int(i)) for i in marker_map.ids])
        self.centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
        self.centre[2] = 0.0

    def pose(self, state: FloatArray, R: FloatArray) -> Pose:
        """The camera's pose over the map for a body in ``state`` (module docstring's frames).

        Parameters
        ----------
        state : ndarray (12,)
            The body's state; its position (m, A) is read.
        R : ndarray (3, 3)
            Attitude, body to A.

        Returns
        -------
        Pose
            ``T_cam_map``: ``p_cam = R @ p_map + t``, m.
        """
        R_map_cam = MAP_FROM_NED @ R @ BODY_TO_CAMERA.T
        position = self.centre + MAP_FROM_NED @ state[:3]
        return Pose(R_map_cam.T, -R_map_cam.T @ position)

    def capture(self, state: FloatArray, R: FloatArray) -> NDArray[np.uint8]:
        """The grey image the camera sees from ``state``: the floor texture's view
        (:meth:`visloc.synth.FloorTexture.render`) with the sensor noise added.

        Parameters
        ----------
        state : ndarray (12,)
            The body's state (position m, A).
        R : ndarray (3, 3)
            Attitude, body to A.

        Returns
        -------
        ndarray (height, width) uint8
            The frame, ``size`` as given to the camera.

        Raises
        ------
        ValueError
            If the view leaves the printed floor (its texture and margin), or the camera is not
            above the floor.
        """
        image = self.floor.render(self.K, self.size, self.pose(state, R), supersample=self.supersample)
        if self.noise_sigma <= 0.0:
            return image
        w, h = self.size
        if self._grain is None:
            g = np.rint(self.rng.normal(0.0, self.noise_sigma, (2 * h, 2 * w)))
            self._grain = np.clip(g, 0, 255).astype(np.uint8), np.clip(-g, 0, 255).astype(np.uint8)
        y, x = int(self.rng.integers(0, h + 1)), int(self.rng.integers(0, w + 1))  # integers(0, (h + 1, w + 1))'s draws
        light, dark = (part[y : y + h, x : x + w] for part in self._grain)
        # uint8 adds and subtracts saturate: the image plus the noise clipped to 0-255, as one add
        # of signed noise would give (one of the two parts is 0 at each pixel), in a tenth of its time
        return cv2.subtract(cv2.add(image, light), dark)

    def body_from_map(self, T_cam_map: Pose) -> tuple[FloatArray, FloatArray]:
        """The body's position and attitude from a camera pose: the inverse of :meth:`pose`.

        Parameters
        ----------
        T_cam_map : Pose
            ``p_cam = R @ p_map + t``, m (e.g. a map fix).

        Returns
        -------
        position : ndarray (3,)
            The body's position (its CoG, where the camera sits), m, in A (NED).
        R : ndarray (3, 3)
            Attitude, body to A.
        """
        R_map_cam = T_cam_map.R.T
        position = MAP_FROM_NED @ (-R_map_cam @ T_cam_map.t - self.centre)
        return position, MAP_FROM_NED @ R_map_cam @ BODY_TO_CAMERA
